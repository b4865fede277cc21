"""Deterministic rollouts: how long a policy (or the zero-action baseline) survives, on nominal
physics or on the fixed randomized physics checkpoints are scored on."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import torch
from tensordict import TensorDict

from rd_pipeline.env.config import EnvConfig, Randomization
from rd_pipeline.env.tracking_env import TrackingEnv


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


def scoring(config: EnvConfig, num_envs: int) -> EnvConfig:
    """Where checkpoints are scored: training's randomized physics (drawn from the scoring
    environment's own seed) with no reset noise, so that the score that may choose a checkpoint
    is one no validation protocol repeats."""
    return dataclasses.replace(
        nominal(config, num_envs),
        randomization=config.randomization,
    )


def survival(
    env: TrackingEnv, policy: Callable[[TensorDict], torch.Tensor], start_frames: torch.Tensor
) -> torch.Tensor:
    """(E,) seconds survived from each start frame (one environment per start), until failure or the motion end."""
    env.reset(torch.arange(env.num_envs), frames=start_frames)
    obs = env.get_observations()
    # The done flags live on the simulation's device (a GPU with the warp backend).
    alive = torch.ones(env.num_envs, dtype=torch.bool, device=env.device)
    steps = torch.zeros(env.num_envs, device=env.device)
    with torch.inference_mode():
        while alive.any():
            obs, _, dones, extras = env.step(policy(obs))
            steps += alive.float()
            alive &= ~dones
    return steps.cpu() / env.control_hz


def zero_action(num_actions: int) -> Callable[[TensorDict], torch.Tensor]:
    """Zero actions: the reference fed straight to PD on residual joints, the default pose on
    absolute ones (so, with `all`, the reference itself)."""
    return lambda obs: torch.zeros(obs.batch_size[0], num_actions)


def scoring_starts(n_frames: int, count: int) -> torch.Tensor:
    """`count` start frames evenly spaced over a motion of `n_frames`, frame 0 first."""
    return torch.arange(count) * (n_frames // count)


def checkpoint_scorer(env: TrackingEnv, policy: Callable[[TensorDict], torch.Tensor]) -> Callable[[], dict[str, float]]:
    """Scores the policy as it is when called: start-zero survival (s) and completion (the mean
    fraction of the motion left that it survives) from one start per environment of `env`, a
    nominal environment of its own. Each call starts the environment and its sampler over from their
    state when the scorer was made (curricula, sigmas, generators, failure statistics), so a
    checkpoint's score depends on its weights alone."""
    fresh = env.state_dict()
    # Worlds that have ended respawn where the sampler says, and their episodes move the curricula
    # the live ones fail by: the sampler starts over too.
    fresh_sampler = env.sampler.state_dict()
    starts = scoring_starts(env.max_episode_length, env.num_envs)
    # The last frame ends an episode, so from frame f the most there is to survive is n - 1 - f steps.
    left_s = (env.max_episode_length - 1 - starts) / env.control_hz

    def score() -> dict[str, float]:
        env.load_state_dict(fresh)
        env.sampler.load_state_dict(fresh_sampler)
        seconds = survival(env, policy, starts)
        return {
            "start_zero_s": round(float(seconds[0]), 2),
            "completion": round(float((seconds / left_s).clamp(max=1.0).mean()), 4),
        }

    return score
