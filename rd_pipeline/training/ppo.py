"""PPO on rsl-rl-lib with a multi-value-head critic: one head per reward group, GAE per head,
advantages summed then normalized (the algorithm's only departure from rsl-rl's PPO)."""

from __future__ import annotations

import torch
from rsl_rl.algorithms import PPO
from rsl_rl.models import MLPModel
from rsl_rl.storage import RolloutStorage
from tensordict import TensorDict

from rd_pipeline.training.advantages import combined_advantage, multi_head_gae
from rd_pipeline.training.distributed import ONE_PROCESS, Ranks
from rd_pipeline.training.ppo_config import PpoConfig


class MultiHeadRolloutStorage(RolloutStorage):
    """Rollout storage whose rewards, values and returns have one column per critic head."""

    def __init__(self, num_envs: int, steps: int, obs: TensorDict, actions: int, heads: int, device: str) -> None:
        super().__init__("rl", num_envs, steps, obs, (actions,), device)
        self.rewards = torch.zeros(steps, num_envs, heads, device=device)
        self.values = torch.zeros(steps, num_envs, heads, device=device)
        self.returns = torch.zeros(steps, num_envs, heads, device=device)

    def add_transition(self, transition: RolloutStorage.Transition) -> None:
        rewards = transition.rewards
        transition.rewards = torch.zeros(self.num_envs, device=self.device)  # the parent copies a scalar column
        step = self.step
        super().add_transition(transition)
        self.rewards[step].copy_(rewards)


UPSTREAM_SOURCES: dict[str, str] = {
    "PPO.process_env_step": "0454dc3eb3ac68291fa35f644d50d9f4977b3c676c2479eeea3358232a0e8ee0",
    "PPO.compute_returns": "c2781a53c4e9c570df595b1585ad1ba90937337e39f6a3f70d8e0be1041e322d",
    "RolloutStorage.add_transition": "0d363337aa552de9f213ec18dca1878094800df4c4c49b58da53c8a7e6e4a468",
}
"""sha256 of the rsl-rl-lib 5.5.1 methods that `MultiHeadPPO` and `MultiHeadRolloutStorage` copy or
rely on (a test compares them with the installed library)."""


class MultiHeadPPO(PPO):
    """rsl-rl PPO whose critic outputs one value per reward group.

    `process_env_step` is rsl-rl's with the time-out bootstrap per head (and no RND);
    `compute_returns` replaces its single-head GAE.
    """

    def process_env_step(self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor, extras: dict) -> None:
        self.transition.rewards = rewards.clone()
        self.transition.dones = dones
        if "time_outs" in extras:  # bootstrap every head on time-outs
            self.transition.rewards += self.gamma * self.transition.values * extras["time_outs"].unsqueeze(1).float()
        self.storage.add_transition(self.transition)
        self.transition.clear()
        self.actor.reset(dones)
        self.critic.reset(dones)

    def compute_returns(self, obs: TensorDict) -> None:
        st = self.storage
        last_values = self.critic(obs).detach()
        advantages, returns = multi_head_gae(
            st.rewards, st.values, st.dones.squeeze(-1), last_values, self.gamma, self.lam
        )
        st.returns = returns
        st.advantages = combined_advantage(advantages).unsqueeze(-1)


def build_ppo(
    obs: TensorDict,
    num_envs: int,
    num_actions: int,
    heads: int,
    config: PpoConfig,
    device: str = "cpu",
    ranks: Ranks = ONE_PROCESS,
) -> MultiHeadPPO:
    """The PPO of one rank; with several ranks, rsl-rl's data-parallel scheme (gradients, the
    adaptive learning rate's KL and the normalizers reduced over the ranks) starting from rank
    0's weights."""
    groups = {"actor": ["policy"], "critic": ["critic"]}
    actor = MLPModel(
        obs,
        groups,
        "actor",
        num_actions,
        list(config.hidden_dims),
        "relu",
        obs_normalization=True,
        distribution_cfg={
            "class_name": "GaussianDistribution",
            "init_std": config.init_noise_std,
            "learn_std": config.learn_noise_std,
        },
    )
    if config.init_output_gain != 1.0:
        _scale_output_layer(actor, config.init_output_gain)
    critic = MLPModel(obs, groups, "critic", heads, list(config.hidden_dims), "relu", obs_normalization=True)
    storage = MultiHeadRolloutStorage(num_envs, config.steps_per_env, obs, num_actions, heads, device)
    ppo = MultiHeadPPO(
        actor,
        critic,
        storage,
        num_learning_epochs=config.learning_epochs,
        num_mini_batches=config.mini_batches,
        clip_param=config.clip,
        gamma=config.gamma,
        lam=config.lam,
        value_loss_coef=config.value_loss_coef,
        entropy_coef=config.entropy_coef,
        learning_rate=config.learning_rate,
        max_grad_norm=config.max_grad_norm,
        desired_kl=config.desired_kl,
        use_mixed_precision=config.mixed_precision,
        device=device,
        multi_gpu_cfg={"global_rank": ranks.rank, "world_size": ranks.world_size} if ranks.distributed else None,
    )
    if ranks.distributed:
        ppo.broadcast_parameters()
    return ppo


def _scale_output_layer(actor: MLPModel, gain: float) -> None:
    """Scale the actor's last linear layer by `gain` and zero its bias: the mean action starts
    near zero, which for a residual policy is the reference's own controller."""
    last = [module for module in actor.mlp.modules() if isinstance(module, torch.nn.Linear)][-1]
    with torch.no_grad():
        last.weight.mul_(gain)
        last.bias.zero_()
