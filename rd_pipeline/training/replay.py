"""A replay buffer kept in time order per environment, and n-step targets read from it.

Each environment's transitions stay in the order they happened, so the n steps after a sampled
one are the next n rows of its column. An episode's end cuts the n-step sum: a termination ends
it without bootstrapping; a time-out bootstraps from the time-out step's own state and action
(the environment has already reset the observation after it, so the true next state is gone).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class NStepBatch:
    """Sampled transitions with their n-step sums and where to bootstrap from."""

    policy_obs: torch.Tensor
    """(B, P) actor observations of the sampled steps."""
    critic_obs: torch.Tensor
    """(B, C) critic observations."""
    actions: torch.Tensor
    """(B, A) the actions taken."""
    returns: torch.Tensor
    """(B,) discounted rewards up to the bootstrap."""
    discount: torch.Tensor
    """(B,) gamma to the power of the steps summed; 0 where the episode terminated."""
    next_policy_obs: torch.Tensor
    """(B, P) actor observations to bootstrap from (its action is the target policy's) ..."""
    next_critic_obs: torch.Tensor
    """(B, C) ... and the critic's."""
    timeout_critic_obs: torch.Tensor
    """(B, C) where a time-out cut the sum: the time-out step's critic observation ..."""
    timeout_actions: torch.Tensor
    """(B, A) ... and action, whose Q stands in for the lost next state."""
    cut_by_timeout: torch.Tensor
    """(B,) True where a time-out cut the sum."""
    weight: torch.Tensor
    """(B,) 0 for a time-out at the sampled step itself (nothing to learn from it), else 1."""


class ReplayBuffer:
    """(capacity / N, N) rows of transitions, a row per step of every environment."""

    def __init__(
        self, num_envs: int, capacity: int, policy_dim: int, critic_dim: int, actions: int, device: str = "cpu"
    ) -> None:
        self.num_envs = num_envs
        self.device = device
        self.rows = max(capacity // num_envs, 2)
        zeros = lambda *shape, dtype=torch.float32: torch.zeros(*shape, dtype=dtype, device=device)
        self.policy_obs = zeros(self.rows, num_envs, policy_dim)
        self.critic_obs = zeros(self.rows, num_envs, critic_dim)
        self.actions = zeros(self.rows, num_envs, actions)
        self.rewards = zeros(self.rows, num_envs)
        self.terminated = zeros(self.rows, num_envs, dtype=torch.bool)
        self.timed_out = zeros(self.rows, num_envs, dtype=torch.bool)
        self.next_row = 0
        self.filled = 0

    def add(
        self,
        policy_obs: torch.Tensor,
        critic_obs: torch.Tensor,
        actions: torch.Tensor,
        rewards: torch.Tensor,
        terminated: torch.Tensor,
        timed_out: torch.Tensor,
    ) -> None:
        """One step of every environment: what it saw, did, earned and how the step ended."""
        row = self.next_row
        self.policy_obs[row] = policy_obs
        self.critic_obs[row] = critic_obs
        self.actions[row] = actions
        self.rewards[row] = rewards
        self.terminated[row] = terminated
        self.timed_out[row] = timed_out
        self.next_row = (row + 1) % self.rows
        self.filled = min(self.filled + 1, self.rows)

    def sample(self, batch: int, n_step: int, gamma: float, generator: torch.Generator) -> NStepBatch:
        """`batch` transitions, each with n steps after it in the buffer, and their n-step targets."""
        usable = self.filled - n_step
        oldest = (self.next_row - self.filled) % self.rows
        device = self.device
        age = torch.randint(0, usable, (batch,), generator=generator, device=device)
        env = torch.randint(0, self.num_envs, (batch,), generator=generator, device=device)
        offsets = torch.arange(n_step + 1, device=device)
        rows = (oldest + age[:, None] + offsets) % self.rows  # (B, n + 1)
        ended = self.terminated[rows[:, :n_step], env[:, None]] | self.timed_out[rows[:, :n_step], env[:, None]]
        # Steps summed: up to and including the first that ended an episode (else all n).
        steps = torch.where(ended.any(1), ended.float().argmax(1) + 1, torch.full_like(env, n_step))
        powers = gamma ** offsets[:n_step].float()
        summed = offsets[None, :n_step] < steps[:, None]
        returns = (self.rewards[rows[:, :n_step], env[:, None]] * powers * summed).sum(1)
        last = rows.gather(1, (steps - 1)[:, None]).squeeze(1)
        after = rows.gather(1, steps[:, None]).squeeze(1)
        terminated = self.terminated[last, env]
        cut = self.timed_out[last, env] & ~terminated
        # A time-out bootstraps from Q(s_last, a_last), which already holds the last reward.
        returns = returns - cut * gamma ** (steps - 1).float() * self.rewards[last, env]
        discount = torch.where(terminated, 0.0, gamma ** torch.where(cut, steps - 1, steps).float())
        first = rows[:, 0]
        return NStepBatch(
            policy_obs=self.policy_obs[first, env],
            critic_obs=self.critic_obs[first, env],
            actions=self.actions[first, env],
            returns=returns,
            discount=discount,
            next_policy_obs=self.policy_obs[after, env],
            next_critic_obs=self.critic_obs[after, env],
            timeout_critic_obs=self.critic_obs[last, env],
            timeout_actions=self.actions[last, env],
            cut_by_timeout=cut,
            weight=(~(cut & (steps == 1))).float(),
        )
