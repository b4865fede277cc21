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
    """Turns policy outputs (N, P) into joint position targets for the P policy joints."""

    def __init__(self, config: ActionConfig, residual_mask: torch.Tensor, default_pos: torch.Tensor,
                 lower: torch.Tensor, upper: torch.Tensor) -> None:
        if config.mode not in ACTION_MODES:
            raise ValueError(f"action mode must be one of {', '.join(ACTION_MODES)}, got '{config.mode}'")
        self.config = config
        self.mask = residual_mask.to(default_pos.dtype) if config.mode == "selective" else torch.ones_like(default_pos)
        self.default_pos, self.lower, self.upper = default_pos, lower, upper

    def targets(self, actions: torch.Tensor, reference_next: torch.Tensor) -> torch.Tensor:
        """Joint targets inside [lower, upper]; masked-out joints follow the reference exactly."""
        scaled = self.config.scale * actions.clamp(-self.config.clip, self.config.clip)
        if self.config.mode == "none":
            target = self.default_pos + scaled
        else:
            target = reference_next + self.mask * scaled
        return torch.maximum(torch.minimum(target, self.upper), self.lower)


def pd_torque(target: torch.Tensor, q: torch.Tensor, qd: torch.Tensor, kp: torch.Tensor, kd: torch.Tensor,
              effort_limit: torch.Tensor) -> torch.Tensor:
    """PD torque toward `target`, clipped to the effort limits (run at every physics step)."""
    return (kp * (target - q) - kd * qd).clamp(-effort_limit, effort_limit)
