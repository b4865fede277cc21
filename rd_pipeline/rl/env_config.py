"""Settings of the tracking environment (appendix tables), as plain frozen dataclasses."""

from __future__ import annotations

from dataclasses import dataclass

from rd_pipeline.rl.actions import ActionConfig


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


@dataclass(frozen=True)
class EnvConfig:
    """The tracking environment."""

    num_envs: int = 64
    """Parallel environments."""
    backend: str = "cpu"
    """Physics backend: `cpu` (C MuJoCo in threads) or `warp` (MuJoCo Warp, the `gpu` extra)."""
    threads: int = 2
    """Worker threads stepping MuJoCo (cpu backend)."""
    physics_dt: float = 0.002
    """500 Hz physics."""
    decimation: int = 10
    """Physics steps per control step (50 Hz policy)."""
    history: int = 3
    """Actor observation frames stacked (short history)."""
    actions: ActionConfig = ActionConfig()
    """Residual action mapping."""
    orientation_limit_rad: float = 0.75
    """Termination: root gravity direction differs from the reference's by more than this."""
    motion_far_init_m: float = 0.5
    """Motion-far termination distance at the start ..."""
    motion_far_min_m: float = 0.3
    """... tightened down to this ..."""
    motion_far_max_m: float = 0.5
    """... and never looser than this."""
    curriculum_degree: float = 1e-5
    """Per-step change of the motion-far threshold and of the penalty scale."""
    curriculum_down_up: tuple[float, float] = (40.0, 42.0)
    """Mean episode length (steps) below which the curricula ease, above which they tighten."""
    adaptive_sigma_alpha: float = 1e-3
    """EMA rate of the adaptive tracking sigma (0 keeps the table values)."""
    penalty_scale: tuple[float, float, float] = (0.8, 0.8, 1.0)
    """Penalty curriculum: initial, min, max."""
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
