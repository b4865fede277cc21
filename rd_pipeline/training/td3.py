"""TD3 behind the same environment and loop as PPO: clipped double Q, n-step returns, target
policy smoothing, delayed actor updates, many updates per sample (FastTD3's recipe).

The actor is rsl-rl's `MLPModel`, as PPO's, so export and validation take either; its Gaussian
head is held and unused (exploration noise is drawn here, a std per environment). The learner
answers the calls the training loop makes of PPO (`act`, `process_env_step`, `compute_returns`,
`update`, `save`, `load`); a resumed run continues the weights, optimizers and normalizers, and
refills its replay buffer (it is not saved: at a million transitions it would outweigh the
checkpoints many times), so unlike PPO's a resumed TD3 run is not bit-for-bit the uninterrupted one.

With several ranks each keeps its own environments, replay buffer and noise, and every update
averages the gradients of each rank's batch (DDP's scheme: an update learns from `ranks x
batch_size` transitions); the normalizers pool every rank's observations (rsl-rl's do once a
process group exists), so the weights stay identical on every rank.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import torch
import torch.distributed as dist
from rsl_rl.models import MLPModel
from rsl_rl.modules import MLP, EmpiricalNormalization
from rsl_rl.utils.utils import reduce_gradients_in_buckets
from tensordict import TensorDict
from torch import nn

from rd_pipeline.training.distributed import ONE_PROCESS, Ranks
from rd_pipeline.training.replay import NStepBatch, ReplayBuffer
from rd_pipeline.training.td3_config import Td3Config

GRADIENT_BUCKET_MB = 25.0
"""rsl-rl PPO's bucket for averaging gradients over ranks: it bounds a packing buffer's size and
leaves the averaged values unchanged, so it is no setting of the learner."""


class TwinQ(nn.Module):
    """Two Q networks on the normalized critic observation and the action."""

    def __init__(self, critic_dim: int, actions: int, hidden_dims: tuple[int, ...]) -> None:
        super().__init__()
        self.normalizer = EmpiricalNormalization(critic_dim)
        self.q1 = MLP(critic_dim + actions, 1, hidden_dims, "relu")
        self.q2 = MLP(critic_dim + actions, 1, hidden_dims, "relu")

    def forward(self, critic_obs: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        joined = torch.cat([self.normalizer(critic_obs), actions], dim=-1)
        return self.q1(joined).squeeze(-1), self.q2(joined).squeeze(-1)


@dataclass
class _Storage:
    """What the training loop reads of PPO's rollout storage."""

    num_transitions_per_env: int


class Td3:
    """TD3 for `num_envs` environments stepping together."""

    def __init__(
        self,
        obs: TensorDict,
        num_envs: int,
        num_actions: int,
        action_bound: float,
        config: Td3Config,
        seed: int,
        device: str = "cpu",
        ranks: Ranks = ONE_PROCESS,
    ) -> None:
        self.config = config
        self.device = device
        self.ranks = ranks
        self.seed = ranks.seed(seed)
        self.num_envs = num_envs
        self.action_bound = action_bound
        self.actor = MLPModel(
            obs,
            {"actor": ["policy"]},
            "actor",
            num_actions,
            list(config.hidden_dims),
            "relu",
            obs_normalization=True,
            distribution_cfg={"class_name": "GaussianDistribution", "init_std": 1.0, "learn_std": False},
        ).to(device)
        critic_dim = obs["critic"].shape[1]
        self.critic = TwinQ(critic_dim, num_actions, config.critic_hidden_dims).to(device)
        if ranks.distributed:
            _broadcast(self.actor)
            _broadcast(self.critic)
        self.actor_target = copy.deepcopy(self.actor).requires_grad_(False)
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=config.learning_rate)
        self.optimizer = torch.optim.Adam(self.critic.parameters(), lr=config.learning_rate)
        self.learning_rate = config.learning_rate
        self.storage = _Storage(config.steps_per_env)
        self.buffer = ReplayBuffer(
            num_envs, config.buffer_size, obs["policy"].shape[1], critic_dim, num_actions, device
        )
        self.generator = torch.Generator(device).manual_seed(self.seed)
        self.noise_std = self._draw_noise_std(num_envs)
        self.updates = 0
        self._pending: tuple[TensorDict, torch.Tensor] | None = None

    # -- collection ----------------------------------------------------------------------
    @torch.no_grad()
    def act(self, obs: TensorDict) -> torch.Tensor:
        """The actor's action with each environment's exploration noise, within the bound."""
        self.actor.update_normalization(obs)
        self.critic.normalizer.update(obs["critic"])
        mean = self.actor(obs, stochastic_output=False)
        noise = torch.randn(mean.shape, generator=self.generator, device=self.device) * self.noise_std[:, None]
        actions = (mean + noise).clamp(-self.action_bound, self.action_bound)
        self._pending = (obs, actions)
        return actions

    def process_env_step(self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor, extras: dict) -> None:
        """Store the step that `act` began; environments that reset draw a new noise std."""
        assert self._pending is not None
        seen, actions = self._pending
        timed_out = extras["time_outs"].bool()
        terminated = dones.bool() & ~timed_out
        self.buffer.add(seen["policy"], seen["critic"], actions, rewards.sum(-1), terminated, timed_out)
        ended = dones.bool()
        if ended.any():
            self.noise_std[ended] = self._draw_noise_std(int(ended.sum()))
        self._pending = None

    def compute_returns(self, obs: TensorDict) -> None:
        """Nothing to do: n-step targets are computed from the buffer when sampled."""

    def _draw_noise_std(self, count: int) -> torch.Tensor:
        low = self.config.noise_std_min
        high = self.config.noise_std_max
        return low + (high - low) * torch.rand(count, generator=self.generator, device=self.device)

    # -- learning ------------------------------------------------------------------------
    def update(self) -> dict[str, float]:
        """`steps_per_env x updates_per_step` gradient updates (none until the buffer holds
        `learning_starts` steps); the mean losses."""
        config = self.config
        if self.buffer.filled < max(config.learning_starts, config.n_step + 1):
            return {"critic": 0.0, "actor": 0.0}
        self.actor.train()
        critic_losses = []
        actor_losses = []
        for _ in range(config.steps_per_env * config.updates_per_step):
            batch = self.buffer.sample(config.batch_size, config.n_step, config.gamma, self.generator)
            critic_losses.append(self._critic_step(batch))
            self.updates += 1
            if self.updates % config.policy_delay == 0:
                actor_losses.append(self._actor_step(batch))
                self._soft_update()
        mean = lambda values: float(sum(values) / len(values)) if values else 0.0
        return {"critic": mean(critic_losses), "actor": mean(actor_losses)}

    def _critic_step(self, batch: NStepBatch) -> float:
        config = self.config
        with torch.no_grad():
            target = batch.returns + batch.discount * self._bootstrap(batch)
        q1, q2 = self.critic(batch.critic_obs, batch.actions)
        loss = (batch.weight * ((q1 - target) ** 2 + (q2 - target) ** 2)).sum() / batch.weight.sum().clamp(min=1)
        self.optimizer.zero_grad()
        loss.backward()
        self._average_gradients(self.critic)
        nn.utils.clip_grad_norm_(self.critic.parameters(), config.max_grad_norm)
        self.optimizer.step()
        return float(loss.detach())

    def _bootstrap(self, batch: NStepBatch) -> torch.Tensor:
        """min over the target twins of Q at the next state under the smoothed target policy, or
        at the time-out step's own state and action where a time-out cut the sum."""
        config = self.config
        next_obs = TensorDict({"policy": batch.next_policy_obs}, batch_size=[len(batch.returns)])
        action = self.actor_target(next_obs, stochastic_output=False)
        noise = torch.randn(action.shape, generator=self.generator, device=self.device) * config.target_noise
        action = (action + noise.clamp(-config.target_noise_clip, config.target_noise_clip)).clamp(
            -self.action_bound, self.action_bound
        )
        ahead = torch.minimum(*self.critic_target(batch.next_critic_obs, action))
        held = torch.minimum(*self.critic_target(batch.timeout_critic_obs, batch.timeout_actions))
        return torch.where(batch.cut_by_timeout, held, ahead)

    def _actor_step(self, batch: NStepBatch) -> float:
        obs = TensorDict({"policy": batch.policy_obs}, batch_size=[len(batch.returns)])
        action = self.actor(obs, stochastic_output=False).clamp(-self.action_bound, self.action_bound)
        q1, _ = self.critic(batch.critic_obs, action)
        loss = -q1.mean()
        self.actor_optimizer.zero_grad()
        loss.backward()
        self._average_gradients(self.actor)
        nn.utils.clip_grad_norm_(self.actor.parameters(), self.config.max_grad_norm)
        self.actor_optimizer.step()
        return float(loss.detach())

    def _average_gradients(self, module: nn.Module) -> None:
        if self.ranks.distributed:
            reduce_gradients_in_buckets(module.parameters(), self.ranks.world_size, GRADIENT_BUCKET_MB)

    def _soft_update(self) -> None:
        tau = self.config.tau
        with torch.no_grad():
            for online, target in ((self.actor, self.actor_target), (self.critic, self.critic_target)):
                for weights, lagging in zip(online.parameters(), target.parameters()):
                    lagging.lerp_(weights, tau)
                for buffer, lagging in zip(online.buffers(), target.buffers()):
                    lagging.copy_(buffer)

    # -- checkpoints ---------------------------------------------------------------------
    def save(self) -> dict:
        return {
            "actor_state_dict": self.actor.state_dict(),
            "critic_state_dict": self.critic.state_dict(),
            "actor_target_state_dict": self.actor_target.state_dict(),
            "critic_target_state_dict": self.critic_target.state_dict(),
            "actor_optimizer_state_dict": self.actor_optimizer.state_dict(),
            "critic_optimizer_state_dict": self.optimizer.state_dict(),
            "generator": self.generator.get_state(),
            "noise_std": self.noise_std,
            "updates": self.updates,
        }

    def load(self, state: dict, load_cfg: dict | None = None, strict: bool = True) -> None:
        self.actor.load_state_dict(state["actor_state_dict"], strict=strict)
        self.critic.load_state_dict(state["critic_state_dict"], strict=strict)
        self.actor_target.load_state_dict(state["actor_target_state_dict"], strict=strict)
        self.critic_target.load_state_dict(state["critic_target_state_dict"], strict=strict)
        self.actor_optimizer.load_state_dict(state["actor_optimizer_state_dict"])
        self.optimizer.load_state_dict(state["critic_optimizer_state_dict"])
        self.updates = int(state["updates"])
        if self.ranks.leader:
            self.generator.set_state(state["generator"])
            self.noise_std = state["noise_std"]
            return
        # A checkpoint holds rank 0's generator: the other ranks continue on streams of their own.
        stream = np.random.SeedSequence([self.seed, self.updates]).generate_state(1)[0]
        self.generator.manual_seed(int(stream))
        self.noise_std = self._draw_noise_std(self.num_envs)


def _broadcast(module: nn.Module) -> None:
    """Rank 0's parameters and buffers (the normalizers' statistics) on every rank."""
    for tensor in module.state_dict().values():
        dist.broadcast(tensor, src=0)
