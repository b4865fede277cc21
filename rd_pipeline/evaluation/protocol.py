"""The sim2sim evaluation protocol: where rollouts start and what counts as a failure."""

from __future__ import annotations

from dataclasses import dataclass

from rd_pipeline.params import require_positive


@dataclass(frozen=True)
class Protocol:
    """How rollouts start and when they fail."""

    grid_s: float = 1.0
    """Fixed-grid protocol: a rollout starts every `grid_s` seconds along the reference."""
    motion_far_m: float = 0.5
    """Failure: a termination body this far from its reference."""
    orientation_limit_rad: float = 0.75
    """Failure: pelvis gravity direction this far from the reference's."""
    threads: int = 2
    """Threads stepping the rollouts' physics."""

    def __post_init__(self) -> None:
        require_positive(self, "grid_s", "motion_far_m", "orientation_limit_rad", "threads")
