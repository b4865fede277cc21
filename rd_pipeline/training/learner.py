"""What the training loop asks of a learner, PPO's or TD3's, and which one a config builds."""

from __future__ import annotations

from typing import Any, Protocol

import torch
from tensordict import TensorDict

from rd_pipeline.env.mdp.rewards import GROUPS
from rd_pipeline.env.tracking_env import TrackingEnv
from rd_pipeline.training.config import TrainConfig
from rd_pipeline.training.distributed import ONE_PROCESS, Ranks


class Learner(Protocol):
    """The calls `trainer.train` makes: rsl-rl PPO's, which TD3 answers too."""

    actor: Any
    """The actor (rsl-rl `MLPModel`): its mean action is the policy that is scored and exported."""
    critic: Any
    storage: Any
    """`num_transitions_per_env`: steps of every environment an iteration collects."""
    optimizer: Any
    """Its `param_groups` take the learning rate a checkpoint saved."""
    learning_rate: float

    def act(self, obs: TensorDict) -> torch.Tensor: ...

    def process_env_step(self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor, extras: dict) -> None: ...

    def compute_returns(self, obs: TensorDict) -> None: ...

    def update(self) -> dict[str, float]: ...

    def save(self) -> dict: ...

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> Any: ...


def build_learner(env: TrackingEnv, config: TrainConfig, ranks: Ranks = ONE_PROCESS) -> Learner:
    """The learner `config.algorithm` names, for `env`'s observations and actions."""
    obs = env.get_observations()
    if config.algorithm == "td3":
        from rd_pipeline.training.td3 import Td3

        bound = config.env.actions.clip
        return Td3(obs, env.num_envs, env.num_actions, bound, config.td3, config.seed, config.env.device, ranks)
    from rd_pipeline.training.ppo import build_ppo

    return build_ppo(obs, env.num_envs, env.num_actions, len(GROUPS), config.ppo, config.env.device, ranks)
