"""Generalized advantage estimation with one value head per reward group (paper, Sec. RL Training Framework).

Each head gets its own GAE over its own reward stream; the PPO objective uses the head-wise
advantages summed, then normalized.
"""

from __future__ import annotations

import torch


def multi_head_gae(
    rewards: torch.Tensor,
    values: torch.Tensor,
    dones: torch.Tensor,
    last_values: torch.Tensor,
    gamma: float,
    lam: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """(advantages, returns), each (T, N, G), from rewards and values (T, N, G), dones (T, N), last_values (N, G)."""
    steps = rewards.shape[0]
    advantages = torch.zeros_like(rewards)
    running = torch.zeros_like(last_values)
    for t in reversed(range(steps)):
        next_values = last_values if t == steps - 1 else values[t + 1]
        not_done = (1.0 - dones[t].float()).unsqueeze(-1)
        delta = rewards[t] + not_done * gamma * next_values - values[t]
        running = delta + not_done * gamma * lam * running
        advantages[t] = running
    return advantages, advantages + values


def combined_advantage(advantages: torch.Tensor) -> torch.Tensor:
    """Head-wise advantages (..., G) summed over heads, then normalized to zero mean and unit std."""
    total = advantages.sum(dim=-1)
    return (total - total.mean()) / (total.std() + 1e-8)
