"""The sim2sim evaluation protocols: where rollouts start, what counts as a failure, and the
physics and sensors they meet (nominal, randomized, other physics)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from rd_pipeline.env.config import Randomization
from rd_pipeline.errors import PipelineError
from rd_pipeline.params import require_non_negative, require_positive


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


@dataclass(frozen=True)
class ObservationNoise:
    """Uniform noise on what the robot's sensors give the policy, half-widths per observation term
    (mjlab's tracking task's ranges); the reference and the last action are exact."""

    joint_pos: float = 0.01
    """Joint positions (rad)."""
    joint_vel: float = 0.5
    """Joint velocities (rad/s)."""
    projected_gravity: float = 0.05
    """Gravity direction in the pelvis frame (unit vector components)."""
    base_ang_vel: float = 0.2
    """Pelvis angular velocity (rad/s)."""

    def __post_init__(self) -> None:
        require_non_negative(self, "joint_pos", "joint_vel", "projected_gravity", "base_ang_vel")


@dataclass(frozen=True)
class RandomizedProtocol:
    """Rollouts on randomized physics: the paper's domain randomization (link mass, pelvis COM,
    friction, PD gains, random force injection, control delay, pushes) with observation noise,
    drawn anew for every rollout from seeds of validation's own."""

    seeds: tuple[int, ...] = (10_001, 10_002, 10_003, 10_004, 10_005, 10_006)
    """One fixed grid of rollouts per seed; the 95% CIs are over seeds (empty: no randomized
    protocol). Training seeds its draws with `train.seed` (small numbers), so these stay apart."""
    models_per_seed: int = 4
    """Randomized models (mass, COM, friction, PD gains) each seed draws; the grid's rollouts
    take them in turn. Delay, force injection, pushes and noise are drawn per rollout."""
    ranges: Randomization = Randomization()
    """What is drawn and from where: the paper's training ranges, whatever ranges the policy
    trained with, so that every policy meets the same physics."""
    observation_noise: ObservationNoise = ObservationNoise()
    """Sensor noise on the policy's observation."""

    def __post_init__(self) -> None:
        require_positive(self, "models_per_seed")


IntegratorName = Literal["Euler", "implicitfast", "implicit", "RK4"]
ConeName = Literal["pyramidal", "elliptic"]


@dataclass(frozen=True)
class OtherPhysics:
    """Rollouts on physics other than training's: the same mesh model with another friction cone
    and timestep (training: pyramidal cone, 500 Hz, and the MJCF's integrator, implicitfast on the
    Unitree models), and the integrator named here."""

    enabled: bool = True
    """Off: no other-physics protocol."""
    integrator: IntegratorName = "implicitfast"
    """MuJoCo integrator."""
    cone: ConeName = "elliptic"
    """Friction cone."""
    physics_hz: float = 1000.0
    """Physics rate; a whole multiple of the policy's control rate."""

    def __post_init__(self) -> None:
        require_positive(self, "physics_hz")

    def describe(self) -> str:
        return f"{self.integrator} integrator, {self.cone} cone, {self.physics_hz:g} Hz"


@dataclass(frozen=True)
class TrackingTolerance:
    """When a control step counts as tracked: alive, and both errors within these."""

    joint_rad: float = 0.2
    """Mean absolute joint error over the policy's joints (rad)."""
    body_m: float = 0.1
    """Mean position error of the tracked bodies relative to the pelvis (m)."""

    def __post_init__(self) -> None:
        require_positive(self, "joint_rad", "body_m")
