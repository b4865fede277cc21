"""Reward terms of the paper's reward table: pure torch functions of a batched tracking state
(`reward_terms.py`, each registered with the critic head it feeds), each configured by a frozen
dataclass (weight, sigma, thresholds) that is a field of `RewardsConfig` named after its function. A
new term is one registered function plus its field.

Tracking terms are Gaussian kernels w * exp(-e / sigma^2) of a squared error e; regularization
terms are penalties w * P (w < 0) scaled by the penalty curriculum. Every term belongs to a group,
and each group is one value head of the critic.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rd_pipeline.env.mdp.reward_terms import (
    GROUPS,
    REWARD_TERMS,
    AirTimeTerm,
    FootForceTerm,
    PenaltyTerm,
    SoftLimitTerm,
    StumbleTerm,
    TermContext,
    TrackingState,
    TrackingTerm,
)
from rd_pipeline.lazy import lazy_import

if TYPE_CHECKING:
    import torch
else:
    torch = lazy_import("torch")


@dataclass(frozen=True)
class RewardsConfig:
    """The paper's reward table: one field per term, named after its function. Tracking terms
    are Gaussian kernels; regularization terms are scaled by the penalty curriculum."""

    body_pos: TrackingTerm = TrackingTerm(2.0, 0.02)
    """Tracked body positions (world)."""
    body_pos_rel: TrackingTerm = TrackingTerm(0.5, 0.02)
    """Tracked body positions relative to the root."""
    keypoint_pos: TrackingTerm = TrackingTerm(1.8, 0.02)
    """VR keypoints (torso, hands), world."""
    keypoint_pos_rel: TrackingTerm = TrackingTerm(0.5, 0.02)
    """VR keypoints relative to the root."""
    feet_pos: TrackingTerm = TrackingTerm(2.0, 0.015)
    """Feet, world."""
    feet_pos_rel: TrackingTerm = TrackingTerm(0.5, 0.015)
    """Feet relative to the root."""
    body_orientation: TrackingTerm = TrackingTerm(0.5, 0.10)
    """Tracked body orientations."""
    body_lin_vel: TrackingTerm = TrackingTerm(0.5, 1.0)
    """Tracked body linear velocities."""
    body_ang_vel: TrackingTerm = TrackingTerm(0.5, 15.0)
    """Tracked body angular velocities."""
    root_pos: TrackingTerm = TrackingTerm(2.0, 0.25)
    """Root position."""
    root_orientation: TrackingTerm = TrackingTerm(0.25, 0.25)
    """Root orientation."""
    joint_pos: TrackingTerm = TrackingTerm(1.0, 0.30)
    """Policy joint positions."""
    joint_vel: TrackingTerm = TrackingTerm(0.5, 30.0)
    """Policy joint velocities."""
    contact_mask: TrackingTerm = TrackingTerm(0.5, 1.0)
    """Feet contact states against the reference's."""
    feet_air_time: AirTimeTerm = AirTimeTerm(1.0)
    """Air time of real steps."""
    torque: PenaltyTerm = PenaltyTerm(-1e-6)
    """Squared joint torques."""
    dof_vel: PenaltyTerm = PenaltyTerm(-1e-4)
    """Squared joint velocities."""
    dof_acc: PenaltyTerm = PenaltyTerm(-2.5e-8)
    """Squared joint accelerations."""
    action_rate: PenaltyTerm = PenaltyTerm(-0.1)
    """Squared action change."""
    action_smoothness: PenaltyTerm = PenaltyTerm(-0.001)
    """Squared second difference of the actions."""
    foot_contact_force: FootForceTerm = FootForceTerm(-0.01)
    """Foot force above the allowance."""
    stumble: StumbleTerm = StumbleTerm(-2.0)
    """Sideways foot force."""
    slippage: PenaltyTerm = PenaltyTerm(-1.0)
    """Squared speed of feet in contact."""
    dof_pos_limits: SoftLimitTerm = SoftLimitTerm(-10.0, soft_fraction=0.9)
    """Joint positions beyond the soft range."""
    dof_vel_limits: SoftLimitTerm = SoftLimitTerm(-1.0, soft_fraction=0.9)
    """Joint velocities beyond the soft limit."""
    torque_limits: SoftLimitTerm = SoftLimitTerm(-0.5, soft_fraction=0.85)
    """Torques beyond the soft limit."""
    termination: PenaltyTerm = PenaltyTerm(-200.0)
    """Ending in a failure."""
    collision: PenaltyTerm = PenaltyTerm(-30.0)
    """Bodies other than the feet touching anything."""


class RewardManager:
    """Evaluates the configured terms and sums them per group (one column per critic head)."""

    def __init__(self, cfg: RewardsConfig, context: TermContext) -> None:
        self.context = context
        self.terms = [(f.name, getattr(cfg, f.name)) for f in dataclasses.fields(cfg)]
        unknown = [name for name, _ in self.terms if name not in REWARD_TERMS]
        if unknown:
            raise KeyError(f"reward terms without a registered function: {', '.join(unknown)}")

    def tracking_sigmas(self) -> dict[str, float]:
        """Table sigma of each tracking term (the adaptive-sigma origins)."""
        return {name: term.sigma for name, term in self.terms if isinstance(term, TrackingTerm)}

    def compute(
        self,
        state: TrackingState,
        penalty_scale: float,
        sigma: dict[str, torch.Tensor] | None = None,
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor], dict[str, torch.Tensor]]:
        """(N, G) reward per group (in `GROUPS` order), (N,) value and (N,) error per term.

        `sigma` replaces a tracking term's table sigma (the adaptive-sigma curriculum); regularization
        penalties are multiplied by `penalty_scale` (the penalty curriculum).
        """
        like = state.joint_pos
        per_group = {group: torch.zeros(like.shape[0], dtype=like.dtype, device=like.device) for group in GROUPS}
        values = {}
        errors = {}
        for name, term in self.terms:
            function, group = REWARD_TERMS[name]
            error = function(state, self.context, term)
            if isinstance(term, TrackingTerm):
                width = (sigma or {}).get(name, term.sigma)
                value = term.weight * torch.exp(-error / width**2)
            elif group == "regularization":
                value = term.weight * penalty_scale * error
            else:
                value = term.weight * error
            values[name] = value
            errors[name] = error
            per_group[group] = per_group[group] + value
        return torch.stack([per_group[g] for g in GROUPS], dim=-1), values, errors


class AdaptiveSigma:
    """Origin-based adaptive tracking sigma (appendix: alpha = 1e-3).

    Each tracking term's sigma^2 follows an exponential moving average of its batch-mean error,
    starting at and never wider than the table value (the origin), so the kernel tightens as
    tracking improves instead of saturating at a reward that no longer separates good from better.
    """

    def __init__(self, alpha: float, table_sigmas: dict[str, float], device: torch.device) -> None:
        self.alpha = alpha
        self.origin = {name: sigma**2 for name, sigma in table_sigmas.items()}
        # 0-d float64 tensors on the training device: the EMA never waits for the device.
        self.variance = {name: torch.tensor(v, dtype=torch.float64, device=device) for name, v in self.origin.items()}

    def update(self, errors: dict[str, torch.Tensor], valid: torch.Tensor) -> None:
        """Move each sigma towards its (N,) errors' mean over the `valid` environments."""
        weights = valid.double() / valid.sum().clamp(min=1)
        for name, origin in self.origin.items():
            batch = (errors[name].double() * weights).sum()
            ema = (1 - self.alpha) * self.variance[name] + self.alpha * batch
            ema = torch.where(valid.any(), ema, self.variance[name])
            # fmin keeps the origin when a batch error is NaN; clamp would carry the NaN on for good.
            self.variance[name] = torch.fmin(ema, ema.new_tensor(origin))

    def sigma(self) -> dict[str, torch.Tensor]:
        return {name: variance**0.5 for name, variance in self.variance.items()}

    def state_dict(self) -> dict[str, float]:
        return {name: float(variance) for name, variance in self.variance.items()}

    def load_state_dict(self, state: dict[str, float]) -> None:
        for name, value in state.items():
            self.variance[name] = torch.tensor(value, dtype=torch.float64, device=self.variance[name].device)
