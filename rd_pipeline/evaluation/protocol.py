"""The sim2sim evaluation protocol: where rollouts start and what counts as a failure."""

from __future__ import annotations

from dataclasses import dataclass

from rd_pipeline.errors import PipelineError
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
    physics_hz: float = 500.0
    """Physics rate of the validation model (the paper's), whatever rate the policy trained at; a
    whole multiple of the policy's control rate."""

    def __post_init__(self) -> None:
        require_positive(self, "grid_s", "motion_far_m", "orientation_limit_rad", "threads", "physics_hz")

    def substeps(self, control_hz: float) -> int:
        """Physics steps per control step of a policy at `control_hz`."""
        steps = round(self.physics_hz / control_hz)
        if steps < 1 or abs(steps * control_hz - self.physics_hz) > 1e-6 * self.physics_hz:
            raise PipelineError(
                f"validate.protocol.physics_hz {self.physics_hz:g} is not a whole multiple of the policy's "
                f"{control_hz:g} Hz control rate"
            )
        return steps
