"""Reward term functions and their configs: pure torch functions of a batched tracking state.

Each function maps (state, context, its config) to an (N,) squared error (tracking terms) or
penalty magnitude (regularization terms); `rd_pipeline.env.mdp.rewards` weighs and sums them. The body
terms average their bodies' squared errors; the joint terms sum over the joints, so their sigma
bounds the whole joint vector's error: the appendix's 30 rad/s for joint velocity would leave a
per-joint mean always near zero against it, a kernel that tells no two policies apart.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rd_pipeline.lazy import lazy_import
from rd_pipeline.params import require_positive

if TYPE_CHECKING:
    import torch
else:
    torch = lazy_import("torch")


@dataclass
class TrackingState:
    """One control step of N environments, robot and reference side by side (world frame)."""

    body_pos: torch.Tensor
    """(N, B, 3) tracked body positions."""
    body_quat: torch.Tensor
    """(N, B, 4) tracked body orientations, wxyz."""
    body_lin_vel: torch.Tensor
    """(N, B, 3)."""
    body_ang_vel: torch.Tensor
    """(N, B, 3)."""
    joint_pos: torch.Tensor
    """(N, P) policy joint positions."""
    joint_vel: torch.Tensor
    """(N, P)."""
    ref_body_pos: torch.Tensor
    """(N, B, 3) reference body positions."""
    ref_body_quat: torch.Tensor
    """(N, B, 4)."""
    ref_body_lin_vel: torch.Tensor
    """(N, B, 3)."""
    ref_body_ang_vel: torch.Tensor
    """(N, B, 3)."""
    ref_joint_pos: torch.Tensor
    """(N, P)."""
    ref_joint_vel: torch.Tensor
    """(N, P)."""
    feet_contact: torch.Tensor
    """(N, 2) bool, from contact forces."""
    ref_feet_contact: torch.Tensor
    """(N, 2) bool, from the reference."""
    feet_force: torch.Tensor
    """(N, 2, 3) contact force on each foot."""
    feet_speed: torch.Tensor
    """(N, 2) horizontal foot speed."""
    torque: torch.Tensor
    """(N, J) applied joint torques (all actuated joints)."""
    joint_acc: torch.Tensor
    """(N, P) joint accelerations."""
    action: torch.Tensor
    """(N, P) current action."""
    last_action: torch.Tensor
    """(N, P)."""
    second_last_action: torch.Tensor
    """(N, P)."""
    feet_air_time: torch.Tensor
    """(N, 2) seconds a foot was in the air, on the step it touches down (0 on every other step)."""
    undesired_contacts: torch.Tensor
    """(N,) count of bodies other than the feet touching the ground."""
    terminated: torch.Tensor
    """(N,) bool, ended by a failure (not by the end of the motion)."""


@dataclass(frozen=True)
class TermContext:
    """What terms know about the robot beside the state: body roles and the platform limits."""

    root: int
    """Index of the root (pelvis) among the tracked bodies."""
    feet: tuple[int, int]
    """Indices of the feet."""
    keypoints: tuple[int, ...]
    """The "VR keypoints" (torso and hands)."""
    joint_lower: torch.Tensor
    """(P,) platform position limits of the policy joints."""
    joint_upper: torch.Tensor
    """(P,)"""
    velocity_limit: torch.Tensor
    """(P,) platform velocity limits of the policy joints."""
    effort_limit: torch.Tensor
    """(J,) platform torque limits of every actuated joint."""


@dataclass(frozen=True)
class TrackingTerm:
    """A Gaussian kernel weight * exp(-e / sigma^2) of a mean squared error e."""

    weight: float
    """Reward at zero error."""
    sigma: float
    """Kernel width (the adaptive-sigma curriculum starts here and only tightens)."""

    def __post_init__(self) -> None:
        require_positive(self, "sigma")


@dataclass(frozen=True)
class PenaltyTerm:
    """weight * P: a penalty (weight < 0) scaled by the penalty curriculum, or a plain bonus."""

    weight: float
    """Scale; negative for penalties."""


@dataclass(frozen=True)
class AirTimeTerm(PenaltyTerm):
    """Feet air time (legged-gym form)."""

    threshold_s: float = 0.25
    """Air time beyond this pays at touchdown."""


@dataclass(frozen=True)
class FootForceTerm(PenaltyTerm):
    """Foot contact force above an allowance."""

    max_force_n: float = 400.0
    """Force (N) above which foot contact is penalized."""


@dataclass(frozen=True)
class StumbleTerm(PenaltyTerm):
    """A foot pushed sideways harder than it is pressed down."""

    ratio: float = 5.0
    """Horizontal force above this multiple of the vertical force counts as a stumble."""


@dataclass(frozen=True)
class SoftLimitTerm(PenaltyTerm):
    """Excess beyond a fraction of a platform limit."""

    soft_fraction: float = 0.9
    """Fraction of the platform limit (of the range, for positions) where the penalty starts."""


GROUPS: tuple[str, ...] = ("body", "root", "joint", "contact", "regularization")
"""The critic's value heads, in column order."""

REWARD_TERMS: dict[str, tuple[Callable[..., torch.Tensor], str]] = {}
"""Term name -> (function, the value head it feeds), filled by `@reward_term`."""


def reward_term(group: str) -> Callable[[Callable[..., torch.Tensor]], Callable[..., torch.Tensor]]:
    """Register a term function under its name, feeding the critic head `group`."""
    if group not in GROUPS:
        raise ValueError(f"unknown reward group '{group}' (groups: {', '.join(GROUPS)})")

    def register(function: Callable[..., torch.Tensor]) -> Callable[..., torch.Tensor]:
        REWARD_TERMS[function.__name__] = (function, group)
        return function

    return register


def _sq(x: torch.Tensor) -> torch.Tensor:
    return (x * x).sum(dim=-1)


def quat_angle(q1: torch.Tensor, q2: torch.Tensor) -> torch.Tensor:
    """Rotation angle between unit quaternions (..., 4), in [0, pi]."""
    dot = (q1 * q2).sum(dim=-1).abs().clamp(max=1.0)
    return 2.0 * torch.acos(dot)


def _relative(pos: torch.Tensor, root: int) -> torch.Tensor:
    return pos - pos[:, root : root + 1]


def _excess(value: torch.Tensor, limit: torch.Tensor) -> torch.Tensor:
    return (value.abs() - limit).clamp(min=0.0).sum(dim=-1)


# Term functions: (state, context, term config) -> (N,) error (tracking) or penalty magnitude.


@reward_term("body")
def body_pos(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    return _sq(s.body_pos - s.ref_body_pos).mean(-1)


@reward_term("body")
def body_pos_rel(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    return _sq(_relative(s.body_pos, c.root) - _relative(s.ref_body_pos, c.root)).mean(-1)


@reward_term("body")
def keypoint_pos(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    return _sq((s.body_pos - s.ref_body_pos)[:, list(c.keypoints)]).mean(-1)


@reward_term("body")
def keypoint_pos_rel(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    error = _relative(s.body_pos, c.root) - _relative(s.ref_body_pos, c.root)
    return _sq(error[:, list(c.keypoints)]).mean(-1)


@reward_term("body")
def feet_pos(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    return _sq((s.body_pos - s.ref_body_pos)[:, list(c.feet)]).mean(-1)


@reward_term("body")
def feet_pos_rel(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    error = _relative(s.body_pos, c.root) - _relative(s.ref_body_pos, c.root)
    return _sq(error[:, list(c.feet)]).mean(-1)


@reward_term("body")
def body_orientation(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    return quat_angle(s.body_quat, s.ref_body_quat).square().mean(-1)


@reward_term("body")
def body_lin_vel(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    return _sq(s.body_lin_vel - s.ref_body_lin_vel).mean(-1)


@reward_term("body")
def body_ang_vel(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    return _sq(s.body_ang_vel - s.ref_body_ang_vel).mean(-1)


@reward_term("root")
def root_pos(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    return _sq(s.body_pos[:, c.root] - s.ref_body_pos[:, c.root])


@reward_term("root")
def root_orientation(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    return quat_angle(s.body_quat[:, c.root], s.ref_body_quat[:, c.root]).square()


@reward_term("joint")
def joint_pos(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    return _sq(s.joint_pos - s.ref_joint_pos)


@reward_term("joint")
def joint_vel(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    return _sq(s.joint_vel - s.ref_joint_vel)


@reward_term("contact")
def contact_mask(s: TrackingState, c: TermContext, cfg: TrackingTerm) -> torch.Tensor:
    """The fraction of feet whose contact state disagrees with the reference."""
    return (s.feet_contact != s.ref_feet_contact).float().mean(-1)


@reward_term("contact")
def feet_air_time(s: TrackingState, c: TermContext, cfg: AirTimeTerm) -> torch.Tensor:
    """At touchdown, the air time beyond the threshold, for feet the reference also has on the
    ground: real steps pay, shuffling or hopping off-reference does not."""
    landed = (s.feet_air_time > 0) & s.ref_feet_contact
    return ((s.feet_air_time - cfg.threshold_s) * landed).sum(-1)


@reward_term("regularization")
def torque(s: TrackingState, c: TermContext, cfg: PenaltyTerm) -> torch.Tensor:
    return _sq(s.torque)


@reward_term("regularization")
def dof_vel(s: TrackingState, c: TermContext, cfg: PenaltyTerm) -> torch.Tensor:
    return _sq(s.joint_vel)


@reward_term("regularization")
def dof_acc(s: TrackingState, c: TermContext, cfg: PenaltyTerm) -> torch.Tensor:
    return _sq(s.joint_acc)


@reward_term("regularization")
def action_rate(s: TrackingState, c: TermContext, cfg: PenaltyTerm) -> torch.Tensor:
    return _sq(s.action - s.last_action)


@reward_term("regularization")
def action_smoothness(s: TrackingState, c: TermContext, cfg: PenaltyTerm) -> torch.Tensor:
    return _sq(s.action - 2 * s.last_action + s.second_last_action)


@reward_term("regularization")
def foot_contact_force(s: TrackingState, c: TermContext, cfg: FootForceTerm) -> torch.Tensor:
    return (s.feet_force.norm(dim=-1) - cfg.max_force_n).clamp(min=0.0).sum(-1)


@reward_term("regularization")
def stumble(s: TrackingState, c: TermContext, cfg: StumbleTerm) -> torch.Tensor:
    sideways = s.feet_force[..., :2].norm(dim=-1)
    return (sideways > cfg.ratio * s.feet_force[..., 2].abs()).any(-1).float()


@reward_term("regularization")
def slippage(s: TrackingState, c: TermContext, cfg: PenaltyTerm) -> torch.Tensor:
    return (s.feet_speed.square() * s.feet_contact).sum(-1)


@reward_term("regularization")
def dof_pos_limits(s: TrackingState, c: TermContext, cfg: SoftLimitTerm) -> torch.Tensor:
    middle = (c.joint_upper + c.joint_lower) / 2
    half = (c.joint_upper - c.joint_lower) / 2
    lower = middle - cfg.soft_fraction * half
    upper = middle + cfg.soft_fraction * half
    return ((lower - s.joint_pos).clamp(min=0) + (s.joint_pos - upper).clamp(min=0)).sum(-1)


@reward_term("regularization")
def dof_vel_limits(s: TrackingState, c: TermContext, cfg: SoftLimitTerm) -> torch.Tensor:
    return _excess(s.joint_vel, cfg.soft_fraction * c.velocity_limit)


@reward_term("regularization")
def torque_limits(s: TrackingState, c: TermContext, cfg: SoftLimitTerm) -> torch.Tensor:
    return _excess(s.torque, cfg.soft_fraction * c.effort_limit)


@reward_term("regularization")
def termination(s: TrackingState, c: TermContext, cfg: PenaltyTerm) -> torch.Tensor:
    return s.terminated.float()


@reward_term("regularization")
def collision(s: TrackingState, c: TermContext, cfg: PenaltyTerm) -> torch.Tensor:
    return s.undesired_contacts.float()
