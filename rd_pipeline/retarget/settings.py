"""Retargeting settings: plain frozen dataclasses, importable without the solver stack."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TargetShaping:
    """How the human motion is shaped into robot targets."""

    smoothing_s: float = 0.12
    """Gaussian sigma (s) on the human joint paths; mocap jitter would otherwise become joint jerk."""
    swing_clearance_m: float = 0.04
    """Height the lowest point of a swinging foot clears the floor by, once lifted."""
    swing_lift_time_s: float = 0.1
    """Time a swing foot takes to rise to its clearance before it travels (and to come down after)."""
    reach_fraction: float = 0.97
    """Fraction of the straight-leg length a planted leg may use; beyond it the body is lowered."""


@dataclass(frozen=True)
class IkWeights:
    """Task costs: position in 1/m, orientation in 1/rad. Larger = followed more closely."""

    root_position: float = 5.0
    """Pelvis position."""
    root_orientation: float = 5.0
    """Pelvis orientation."""
    torso_orientation: float = 3.0
    """Torso orientation."""
    feet_position: float = 100.0
    """Feet position (planted feet must not slide)."""
    feet_orientation: float = 30.0
    """Feet orientation (planted feet stay flat)."""
    limb_position: float = 0.5
    """Knees, hips, shoulders, elbows and hands."""
    posture: float = 0.05
    """Pull toward the default pose, for joints the key bodies leave free."""
    damping: float = 0.05
    """Levenberg-Marquardt damping of the QP."""


@dataclass(frozen=True)
class IkSettings:
    """How the per-frame solve runs."""

    iterations: int = 2
    """Solver iterations per frame (warm started from the previous frame)."""
    solver: str = "daqp"
    """QP solver name (qpsolvers)."""
    velocity_margin: float = 0.95
    """Fraction of each joint's velocity limit a frame step may use."""
    collision_margin_m: float = 0.02
    """Minimum distance kept between configured collision pairs."""
    collision_detection_m: float = 0.15
    """Distance under which a collision pair enters the QP."""
    root_speed_m_s: float = 4.0
    """Bound on the pelvis speed per axis (m/s), applied per frame."""
    root_angular_speed_rad_s: float = 12.0
    """Bound on the pelvis angular speed per axis (rad/s), applied per frame."""
    trajectory_smoothing_s: float = 0.03
    """Gaussian sigma (s) of the sequence-level smoothing of the solved trajectory (0: none)."""
    refine_iterations: int = 2
    """Iterations per frame of the feet refinement after smoothing."""
    refine_posture_cost: float = 5.0
    """How strongly the refinement holds joints at their smoothed values."""
    lm_damping: float = 1.0
    """Error-scaled damping of the frame tasks: keeps the solve calm near singular arms and legs."""
