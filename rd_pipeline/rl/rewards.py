"""Reward terms of the paper's reward table, as pure torch functions of a batched tracking state.

Tracking terms are Gaussian kernels w * exp(-e / sigma^2) of a mean squared error e; regularization
terms are penalties w * P (w < 0) scaled by the penalty curriculum. Every term belongs to a group,
and each group is one value head of the critic.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch


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
class RewardIndices:
    """Which tracked bodies play which role."""

    root: int
    """Index of the root (pelvis) among the tracked bodies."""
    feet: tuple[int, int]
    """Indices of the feet."""
    keypoints: tuple[int, ...]
    """The "VR keypoints" (torso and hands)."""


@dataclass(frozen=True)
class RewardLimits:
    """Soft limits (the appendix's 0.90 / 0.90 / 0.85 of the platform limits, applied by the caller)."""

    joint_lower: torch.Tensor
    """(P,)"""
    joint_upper: torch.Tensor
    """(P,)"""
    joint_velocity: torch.Tensor
    """(P,)"""
    torque: torch.Tensor
    """(J,)"""
    max_foot_force: float = 400.0
    """N, above which foot contact force is penalized."""


@dataclass(frozen=True)
class RewardTerm:
    """One line of the reward table."""

    name: str
    """Term name (logged per term)."""
    group: str
    """Value head it feeds."""
    weight: float
    """Scale; negative for penalties."""
    sigma: float | None
    """Gaussian width for tracking terms; None for penalties."""
    error: Callable[[TrackingState, RewardIndices, RewardLimits], torch.Tensor]
    """(N,) mean squared error (tracking) or penalty magnitude (regularization)."""


def _sq(x: torch.Tensor) -> torch.Tensor:
    return (x * x).sum(dim=-1)


def quat_angle(q1: torch.Tensor, q2: torch.Tensor) -> torch.Tensor:
    """Rotation angle between unit quaternions (..., 4), in [0, pi]."""
    dot = (q1 * q2).sum(dim=-1).abs().clamp(max=1.0)
    return 2.0 * torch.acos(dot)


def _relative(pos: torch.Tensor, root: int) -> torch.Tensor:
    return pos - pos[:, root : root + 1]


def _feet(x: torch.Tensor, i: RewardIndices) -> torch.Tensor:
    return x[:, list(i.feet)]


def _keys(x: torch.Tensor, i: RewardIndices) -> torch.Tensor:
    return x[:, list(i.keypoints)]


def _excess(value: torch.Tensor, limit: torch.Tensor) -> torch.Tensor:
    return (value.abs() - limit).clamp(min=0.0).sum(dim=-1)


TERMS: tuple[RewardTerm, ...] = (
    RewardTerm("body_pos", "body", 2.0, 0.02, lambda s, i, lim: _sq(s.body_pos - s.ref_body_pos).mean(-1)),
    RewardTerm("body_pos_rel", "body", 0.5, 0.02,
               lambda s, i, lim: _sq(_relative(s.body_pos, i.root) - _relative(s.ref_body_pos, i.root)).mean(-1)),
    RewardTerm("keypoint_pos", "body", 1.8, 0.02, lambda s, i, lim: _sq(_keys(s.body_pos - s.ref_body_pos, i)).mean(-1)),
    RewardTerm("keypoint_pos_rel", "body", 0.5, 0.02,
               lambda s, i, lim: _sq(_keys(_relative(s.body_pos, i.root) - _relative(s.ref_body_pos, i.root), i)).mean(-1)),
    RewardTerm("feet_pos", "body", 2.0, 0.015, lambda s, i, lim: _sq(_feet(s.body_pos - s.ref_body_pos, i)).mean(-1)),
    RewardTerm("feet_pos_rel", "body", 0.5, 0.015,
               lambda s, i, lim: _sq(_feet(_relative(s.body_pos, i.root) - _relative(s.ref_body_pos, i.root), i)).mean(-1)),
    RewardTerm("body_orientation", "body", 0.5, 0.10, lambda s, i, lim: quat_angle(s.body_quat, s.ref_body_quat).square().mean(-1)),
    RewardTerm("body_lin_vel", "body", 0.5, 1.0, lambda s, i, lim: _sq(s.body_lin_vel - s.ref_body_lin_vel).mean(-1)),
    RewardTerm("body_ang_vel", "body", 0.5, 15.0, lambda s, i, lim: _sq(s.body_ang_vel - s.ref_body_ang_vel).mean(-1)),
    RewardTerm("root_pos", "root", 2.0, 0.25, lambda s, i, lim: _sq(s.body_pos[:, i.root] - s.ref_body_pos[:, i.root])),
    RewardTerm("root_orientation", "root", 0.25, 0.25,
               lambda s, i, lim: quat_angle(s.body_quat[:, i.root], s.ref_body_quat[:, i.root]).square()),
    RewardTerm("joint_pos", "joint", 1.0, 0.30, lambda s, i, lim: _sq(s.joint_pos - s.ref_joint_pos)),
    RewardTerm("joint_vel", "joint", 0.5, 30.0, lambda s, i, lim: _sq(s.joint_vel - s.ref_joint_vel)),
    # Contact mask: the kernel of the fraction of feet whose contact state disagrees with the reference.
    RewardTerm("contact_mask", "contact", 0.5, 1.0,
               lambda s, i, lim: (s.feet_contact != s.ref_feet_contact).float().mean(-1)),
    # Feet air time (legged-gym form): at touchdown, the air time beyond 0.25 s, for feet the reference
    # also has on the ground, so real steps pay and shuffling or hopping off-reference does not.
    RewardTerm("feet_air_time", "contact", 1.0, None,
               lambda s, i, lim: ((s.feet_air_time - 0.25) * ((s.feet_air_time > 0) & s.ref_feet_contact)).sum(-1)),
    RewardTerm("torque", "regularization", -1e-6, None, lambda s, i, lim: _sq(s.torque)),
    RewardTerm("dof_vel", "regularization", -1e-4, None, lambda s, i, lim: _sq(s.joint_vel)),
    RewardTerm("dof_acc", "regularization", -2.5e-8, None, lambda s, i, lim: _sq(s.joint_acc)),
    RewardTerm("action_rate", "regularization", -0.1, None, lambda s, i, lim: _sq(s.action - s.last_action)),
    RewardTerm("action_smoothness", "regularization", -0.001, None,
               lambda s, i, lim: _sq(s.action - 2 * s.last_action + s.second_last_action)),
    RewardTerm("foot_contact_force", "regularization", -0.01, None,
               lambda s, i, lim: (s.feet_force.norm(dim=-1) - lim.max_foot_force).clamp(min=0.0).sum(-1)),
    RewardTerm("stumble", "regularization", -2.0, None,
               lambda s, i, lim: (s.feet_force[..., :2].norm(dim=-1) > 5 * s.feet_force[..., 2].abs()).any(-1).float()),
    RewardTerm("slippage", "regularization", -1.0, None, lambda s, i, lim: (s.feet_speed.square() * s.feet_contact).sum(-1)),
    RewardTerm("dof_pos_limits", "regularization", -10.0, None,
               lambda s, i, lim: ((lim.joint_lower - s.joint_pos).clamp(min=0) + (s.joint_pos - lim.joint_upper).clamp(min=0)).sum(-1)),
    RewardTerm("dof_vel_limits", "regularization", -1.0, None, lambda s, i, lim: _excess(s.joint_vel, lim.joint_velocity)),
    RewardTerm("torque_limits", "regularization", -0.5, None, lambda s, i, lim: _excess(s.torque, lim.torque)),
    RewardTerm("termination", "regularization", -200.0, None, lambda s, i, lim: s.terminated.float()),
    RewardTerm("collision", "regularization", -30.0, None, lambda s, i, lim: s.undesired_contacts.float()),
)
"""The paper's reward table."""

GROUPS: tuple[str, ...] = tuple(dict.fromkeys(term.group for term in TERMS))


def compute_rewards(
    state: TrackingState, indices: RewardIndices, limits: RewardLimits, penalty_scale: float,
    sigma: dict[str, float] | None = None, terms: tuple[RewardTerm, ...] = TERMS,
) -> tuple[torch.Tensor, dict[str, torch.Tensor], dict[str, torch.Tensor]]:
    """(N, G) reward per group (the critic's heads, in `GROUPS` order), (N,) value per term and
    (N,) error per term.

    `sigma` replaces a tracking term's table sigma (the adaptive-sigma curriculum); regularization
    penalties are multiplied by `penalty_scale` (the penalty curriculum).
    """
    per_group = {group: torch.zeros(state.joint_pos.shape[0], dtype=state.joint_pos.dtype) for group in GROUPS}
    values, errors = {}, {}
    for term in terms:
        error = term.error(state, indices, limits)
        if term.sigma is not None:
            width = (sigma or {}).get(term.name, term.sigma)
            value = term.weight * torch.exp(-error / width**2)
        elif term.group == "regularization":
            value = term.weight * penalty_scale * error
        else:
            value = term.weight * error
        values[term.name], errors[term.name] = value, error
        per_group[term.group] = per_group[term.group] + value
    return torch.stack([per_group[g] for g in GROUPS], dim=-1), values, errors


class AdaptiveSigma:
    """Origin-based adaptive tracking sigma (appendix: alpha = 1e-3).

    Each tracking term's sigma^2 follows an exponential moving average of its batch-mean error,
    starting at and never wider than the table value (the origin), so the kernel tightens as
    tracking improves instead of saturating at a reward that no longer separates good from better.
    """

    def __init__(self, alpha: float, terms: tuple[RewardTerm, ...] = TERMS) -> None:
        self.alpha = alpha
        self.origin = {t.name: t.sigma**2 for t in terms if t.sigma is not None}
        self.variance = dict(self.origin)

    def update(self, errors: dict[str, torch.Tensor]) -> None:
        for name, origin in self.origin.items():
            ema = (1 - self.alpha) * self.variance[name] + self.alpha * float(errors[name].mean())
            self.variance[name] = min(origin, ema)

    def sigma(self) -> dict[str, float]:
        return {name: variance**0.5 for name, variance in self.variance.items()}
