"""Settings of the tracking environment (appendix tables), as plain frozen dataclasses: every term's
weights, widths, thresholds and scales are fields here, so they are in the train artifact key."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from rd_pipeline.env.mdp.actions import ActionConfig
from rd_pipeline.env.mdp.curricula import CurriculaConfig
from rd_pipeline.env.mdp.observations import ObservationsConfig
from rd_pipeline.env.mdp.rewards import RewardsConfig
from rd_pipeline.env.mdp.terminations import TerminationsConfig
from rd_pipeline.params import require_positive

CollisionModel = Literal["primitive", "mesh"]
"""`primitive`: boxes fitted to the collision meshes (training); `mesh`: the robot's own meshes (validation)."""


@dataclass(frozen=True)
class Randomization:
    """Domain randomization (appendix, "Domain Randomization and Motion Resampling")."""

    enabled: bool = True
    """Off for nominal-physics evaluation."""
    push_interval_s: tuple[float, float] = (5.0, 10.0)
    """Time between pushes."""
    push_max_speed: float = 0.5
    """Largest horizontal velocity change of a push (m/s)."""
    com_offset_m: float = 0.1
    """Pelvis centre-of-mass offset range per axis (+-)."""
    mass_factor: tuple[float, float] = (0.9, 1.2)
    """Link mass factor."""
    friction_factor: tuple[float, float] = (0.5, 1.25)
    """Ground-contact friction factor."""
    pd_factor: tuple[float, float] = (0.85, 1.15)
    """kp and kd factors."""
    torque_rfi: float = 0.1
    """Random force injection, as a fraction of each joint's effort limit ..."""
    torque_rfi_factor: tuple[float, float] = (0.5, 1.5)
    """... times a per-environment factor."""
    max_delay_steps: int = 2
    """Control delay drawn from 0..max_delay_steps control steps."""


PhysicsBackendName = Literal["rollout", "cpu", "warp"]


@dataclass(frozen=True)
class EnvConfig:
    """The tracking environment: its physics, and the terms it is built from."""

    num_envs: int = 64
    """Parallel environments."""
    backend: PhysicsBackendName = "rollout"
    """Physics backend: `rollout` (C MuJoCo batched by `mujoco.rollout`, GIL-free threads), `cpu`
    (one C MuJoCo call per environment from Python threads) or `warp` (MuJoCo Warp, the `gpu` extra)."""
    device: str = "cpu"
    """Torch device of the simulation state and the training tensors: `cpu`, or `cuda` / `cuda:N`
    with the warp backend (physics and learning then share GPU memory)."""
    threads: int = 2
    """Threads stepping C MuJoCo (rollout and cpu backends): one per core. The ranks of a
    data-parallel run on one machine share them (each steps on threads / ranks there)."""
    collision: CollisionModel = "primitive"
    """Collision geometry of the training model: `primitive` (fitted capsules and boxes, self-collision
    only in the robot config's pairs) or `mesh` (the MJCF's meshes, every pair); validation always
    uses the meshes."""
    physics_dt: float = 0.002
    """Physics step of training (the paper: 500 Hz; mjlab's tracking task: 0.005, 200 Hz).
    Validation always steps at the paper's 500 Hz, so sim2sim measures the gap."""
    decimation: int = 10
    """Physics steps per control step; `physics_dt * decimation` is the 50 Hz control step."""
    solver_iterations: int = 100
    """Constraint-solver iterations per physics step (MuJoCo's default 100; mjlab's tracking task:
    Newton with 10). Validation keeps MuJoCo's default."""
    ls_iterations: int = 50
    """Line-search iterations per solver iteration (MuJoCo's default 50; mjlab: 20)."""
    history: int = 3
    """Actor observation frames stacked (short history)."""
    contact_threshold_n: float = 1.0
    """A body touches something when its contact force exceeds this (N)."""
    actions: ActionConfig = ActionConfig()
    """Residual action mapping."""
    observations: ObservationsConfig = ObservationsConfig()
    """Actor observation scales."""
    rewards: RewardsConfig = RewardsConfig()
    """The reward table."""
    terminations: TerminationsConfig = TerminationsConfig()
    """Failure tests."""
    curricula: CurriculaConfig = CurriculaConfig()
    """Termination, penalty and sigma curricula."""
    rsi_joint_pos: float = 0.1
    """RSI noise: joint positions (rad)."""
    rsi_joint_vel: float = 0.15
    """RSI noise: joint velocities (rad/s)."""
    rsi_root_pos_m: float = 0.05
    """RSI noise: root position."""
    rsi_root_rot_deg: float = 10.0
    """RSI noise: root rotation."""
    rsi_root_vel: float = 0.01
    """RSI noise: root linear and angular velocity."""
    randomization: Randomization = Randomization()
    """Domain randomization."""

    def __post_init__(self) -> None:
        require_positive(
            self,
            "num_envs",
            "threads",
            "physics_dt",
            "decimation",
            "solver_iterations",
            "ls_iterations",
            "history",
        )
