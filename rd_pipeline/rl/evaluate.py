"""Deterministic rollouts on nominal physics: how long a policy (or the zero-action baseline) survives."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import torch
from tensordict import TensorDict

from rd_pipeline.rl.env import TrackingEnv
from rd_pipeline.rl.env_config import EnvConfig, Randomization


def nominal(config: EnvConfig, num_envs: int) -> EnvConfig:
    """The same environment without randomization or reset noise."""
    return dataclasses.replace(
        config,
        num_envs=num_envs,
        randomization=Randomization(enabled=False),
        rsi_joint_pos=0.0,
        rsi_joint_vel=0.0,
        rsi_root_pos_m=0.0,
        rsi_root_rot_deg=0.0,
        rsi_root_vel=0.0,
    )


def survival(
    env: TrackingEnv, policy: Callable[[TensorDict], torch.Tensor], start_frames: torch.Tensor
) -> torch.Tensor:
    """(E,) seconds survived from each start frame (one environment per start), until failure or the motion end."""
    env.reset(torch.arange(env.num_envs), frames=start_frames)
    obs = env.get_observations()
    alive = torch.ones(env.num_envs, dtype=torch.bool)
    steps = torch.zeros(env.num_envs)
    with torch.inference_mode():
        while alive.any():
            obs, _, dones, extras = env.step(policy(obs))
            steps += alive.float()
            alive &= ~dones
    return steps / 50.0


def zero_action(num_actions: int) -> Callable[[TensorDict], torch.Tensor]:
    """Zero actions: the reference fed straight to PD on residual joints, the default pose on
    absolute ones (so, with `all`, the reference itself)."""
    return lambda obs: torch.zeros(obs.batch_size[0], num_actions)
