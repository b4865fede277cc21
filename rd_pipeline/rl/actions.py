"""Residual actions: q_tar = q_ref(t+1) + m * (scale * a), clipped and projected to the joint limits."""

from __future__ import annotations

from dataclasses import dataclass

import torch

ACTION_MODES = ("selective", "all", "none")


@dataclass(frozen=True)
class ActionConfig:
    """Paper, Table "Control, Initialization, and Termination Parameters"."""

    mode: str = "selective"
    """`selective` (the robot's residual mask), `all` (every policy joint), `none` (absolute targets
    around the default pose, the ablation baseline)."""
    scale: float = 0.25
    """Action scale."""
    clip: float = 100.0
    """Actions are clipped to +-clip before scaling."""


class ResidualActions:
    """Turns policy outputs (N, A) into joint position targets for the P policy joints.

    The policy outputs one value per joint it may move (`active`): the masked joints in `selective`
    mode, every policy joint otherwise. Outputs for joints the mask zeroes would only add noise to
    the PPO update (their KL, entropy and action-rate terms carry no signal), so they do not exist.
    """

    def __init__(self, config: ActionConfig, residual_mask: torch.Tensor, default_pos: torch.Tensor,
                 lower: torch.Tensor, upper: torch.Tensor) -> None:
        if config.mode not in ACTION_MODES:
            raise ValueError(f"action mode must be one of {', '.join(ACTION_MODES)}, got '{config.mode}'")
        self.config = config
        self.active = torch.nonzero(residual_mask).flatten() if config.mode == "selective" else torch.arange(len(default_pos))
        self.default_pos, self.lower, self.upper = default_pos, lower, upper

    @property
    def size(self) -> int:
        """A, the policy's action dimension."""
        return len(self.active)

    def targets(self, actions: torch.Tensor, reference_next: torch.Tensor) -> torch.Tensor:
        """(N, P) joint targets inside [lower, upper]; joints outside `active` follow the reference exactly."""
        scaled = self.config.scale * actions.clamp(-self.config.clip, self.config.clip)
        base = self.default_pos.expand_as(reference_next) if self.config.mode == "none" else reference_next
        target = base.clone()
        target[:, self.active] += scaled.to(target.dtype)
        return torch.maximum(torch.minimum(target, self.upper), self.lower)
