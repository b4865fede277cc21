"""What a validation is configured by (the `validate` stage's params); light, so planning a run
loads neither torch nor MuJoCo."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from rd_pipeline.evaluation.protocol import OtherPhysics, Protocol, RandomizedProtocol, TrackingTolerance
from rd_pipeline.params import require_positive
from rd_pipeline.viz.render_config import RenderConfig


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
