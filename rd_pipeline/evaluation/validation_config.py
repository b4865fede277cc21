"""What a validation is configured by (the `validate` stage's params); light, so planning a run
loads neither torch nor MuJoCo."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from rd_pipeline.evaluation.protocol import OtherPhysics, Protocol, RandomizedProtocol, TrackingTolerance
from rd_pipeline.params import require_non_negative, require_positive


@dataclass(frozen=True)
class RenderConfig:
    """Pictures of the start-zero rollout beside its reference (MuJoCo offscreen, headless)."""

    enabled: bool = True
    """Off: no filmstrip and no video."""
    width: int = 480
    """Pixels of one view, across."""
    height: int = 360
    """Pixels of one view, down."""
    filmstrip_frames: int = 6
    """Views in the filmstrip, evenly spaced over the clip."""
    video_fps: int = 25
    """Frame rate of the MP4 (the policy's steps are subsampled to it)."""
    video_max_s: float = 20.0
    """The MP4 shows at most this much of the rollout (a whole take would take minutes to render)."""
    timeout_s: float = 600.0
    """Rendering that takes longer is given up, and the report says so."""
    beside_m: float = 1.0
    """How far to the side of the tracked robot the reference is drawn."""
    multisamples: int = 4
    """Anti-aliasing samples per pixel (MuJoCo's `offsamples`); 0 renders about twice as fast on
    a machine without a GPU, where OpenGL runs in software."""

    def __post_init__(self) -> None:
        require_positive(
            self, "width", "height", "filmstrip_frames", "video_fps", "video_max_s", "timeout_s", "beside_m"
        )
        require_non_negative(self, "multisamples")


@dataclass(frozen=True)
class ValidationConfig:
    """The evaluation protocols and what the report shows of them."""

    protocol: Protocol = Protocol()
    """Start grid, failure thresholds, threads (every protocol's)."""
    randomized: RandomizedProtocol = RandomizedProtocol()
    """Rollouts under the paper's randomization and sensor noise, on seeds of their own."""
    other_physics: OtherPhysics = OtherPhysics()
    """Rollouts on physics other than training's."""
    tracking: TrackingTolerance = TrackingTolerance()
    """When a step counts as tracked, for the share of the clip tracked."""
    render: RenderConfig = RenderConfig()
    """The filmstrip and the video."""
    bootstrap_seed: int = 0
    """Seeds the bootstrap of the drift CI."""
    bootstrap_resamples: int = 1000
    """Resamples of the drift CI's bootstrap."""
    recorded_observations: int = 2000
    """Observations of the policy's rollouts kept to compare the two runtimes on."""
    runtime: Literal["torchscript", "onnx"] = "torchscript"
    """Which exported file runs the loop: `policy.pt` on torch or `policy.onnx` on onnxruntime; the
    other one is checked against it on the observations the loop recorded."""

    def __post_init__(self) -> None:
        require_positive(self, "recorded_observations", "bootstrap_resamples")
