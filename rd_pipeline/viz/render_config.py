"""How the pictures of a rollout look (the `validate` stage's `render` params).

A module of its own so the renderer's process imports neither the validation's protocols nor,
through them, the deferred torch: matplotlib looks at `sys.modules["torch"]` when it plots, which
would load it (seconds) in a process that never uses it.
"""

from __future__ import annotations

from dataclasses import dataclass

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
    shadows: bool = True
    """Shadows and the floor's reflections. Off, a frame renders about five times faster where
    OpenGL runs in software (llvmpipe), with fewer depth cues."""

    def __post_init__(self) -> None:
        require_positive(
            self, "width", "height", "filmstrip_frames", "video_fps", "video_max_s", "timeout_s", "beside_m"
        )
        require_non_negative(self, "multisamples")
