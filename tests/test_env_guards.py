"""The training environment's guard against physics that blows up in one world."""

from __future__ import annotations

from pathlib import Path

import torch
from conftest import h1_2_dance_env

from rd_pipeline.env.config import EnvConfig, Randomization
from rd_pipeline.env.mdp.actions import ActionConfig
from rd_pipeline.env.mdp.rewards import GROUPS
from rd_pipeline.env.tracking_env import TrackingEnv
from rd_pipeline.training.ppo import build_ppo
from rd_pipeline.training.ppo_config import PpoConfig
from rd_pipeline.training.trainer import train

# Without randomization nothing else draws from the generator, so the worlds that did not blow up
# must match an untouched environment bit for bit.
CONFIG = EnvConfig(num_envs=4, threads=2, actions=ActionConfig(mode="all"), randomization=Randomization(enabled=False))
BROKEN = 2
OTHERS = [0, 1, 3]


def _poison_once(env: TrackingEnv, after_calls: int) -> None:
    """Make the backend hand back a NaN velocity in world `BROKEN` on its `after_calls`-th step."""
    real_step = env.backend.step
    calls = [0]

    def step(ctrl: torch.Tensor, substeps: int, joint_force: torch.Tensor | None = None):
        state = real_step(ctrl, substeps, joint_force)
        calls[0] += 1
        if calls[0] == after_calls:
            state.qvel[BROKEN, 0] = float("nan")
        return state

    env.backend.step = step  # type: ignore[method-assign]


def test_a_world_gone_nonfinite_resets_alone_and_is_counted() -> None:
    poisoned = h1_2_dance_env(CONFIG)
    clean = h1_2_dance_env(CONFIG)
    zero = torch.zeros(CONFIG.num_envs, poisoned.num_actions)
    _poison_once(poisoned, after_calls=2)
    counted = []
    for _ in range(3):
        obs, rewards, dones, extras = poisoned.step(zero)
        clean_obs, clean_rewards, clean_dones, clean_extras = clean.step(zero)
        assert clean_extras["nonfinite"] == 0
        for value in (obs["policy"], obs["critic"], rewards):
            assert torch.isfinite(value).all()
        assert torch.equal(obs["policy"][OTHERS], clean_obs["policy"][OTHERS])
        # The adaptive sigmas leave the broken world out of their batch mean, so later rewards
        # differ in the last digits; the step it broke on is still exact.
        assert torch.allclose(rewards[OTHERS], clean_rewards[OTHERS], rtol=1e-3, atol=1e-6)
        assert torch.equal(poisoned.backend.state.qpos[OTHERS], clean.backend.state.qpos[OTHERS])
        counted.append(extras["nonfinite"])
        if extras["nonfinite"]:
            assert dones[BROKEN] and not dones[OTHERS].any()
            assert rewards[BROKEN].abs().sum() == 0
            assert torch.equal(rewards[OTHERS], clean_rewards[OTHERS])
            assert poisoned.episode_length_buf[BROKEN] == 0  # reset this step
    assert counted == [0, 1, 0]
    assert poisoned.episode_length_buf[OTHERS].tolist() == [3, 3, 3]


def test_the_training_log_counts_the_worlds_that_went_nonfinite(tmp_path: Path) -> None:
    env = h1_2_dance_env(CONFIG)
    ppo = build_ppo(env.get_observations(), 4, env.num_actions, len(GROUPS), PpoConfig(steps_per_env=6))
    _poison_once(env, after_calls=9)  # the second iteration's third step
    rows = train(env, ppo, iterations=2, out_dir=tmp_path, checkpoint_every=2)
    assert [row["nonfinite_resets"] for row in rows] == [0, 1]
    assert all(torch.isfinite(p).all() for p in ppo.actor.parameters())
