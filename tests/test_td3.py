"""TD3 behind the tracking environment: it learns in process, and trains (on two ranks), resumes,
exports and validates through the same command as PPO."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from conftest import cli, h1_2_dance_env

from rd_pipeline.env.config import EnvConfig
from rd_pipeline.training.log import checkpoints_by_iteration, read_training_log
from rd_pipeline.training.td3 import Td3
from rd_pipeline.training.td3_config import Td3Config

SMALL = Td3Config(steps_per_env=4, batch_size=32, learning_starts=4, hidden_dims=(32, 32), critic_hidden_dims=(32, 32))
"""Small networks and batches: a check of the mechanics, not of learning."""


def _collect(td3: Td3, env, steps: int) -> None:
    obs = env.get_observations()
    with torch.inference_mode():
        for _ in range(steps):
            obs, rewards, dones, extras = env.step(td3.act(obs))
            td3.process_env_step(obs, rewards, dones, extras)


@pytest.mark.slow  # the H1-2 take's import and 40 steps: about 12 s
def test_updates_move_the_critic_toward_its_targets_and_actions_stay_in_the_bound() -> None:
    torch.manual_seed(0)
    env = h1_2_dance_env(EnvConfig(num_envs=4, threads=1))
    td3 = Td3(env.get_observations(), env.num_envs, env.num_actions, 0.3, SMALL, seed=0)
    assert td3.update() == {"critic": 0.0, "actor": 0.0}  # nothing to learn from yet
    _collect(td3, env, 40)
    actions = td3.act(env.get_observations())
    assert actions.abs().max() <= 0.3 and actions.std() > 0.01
    before = [p.clone() for p in td3.actor.parameters()]
    first = td3.update()["critic"]
    for _ in range(30):
        last = td3.update()["critic"]
    assert 0 < last < first  # the critic fits the replayed targets
    assert any(not torch.equal(a, b) for a, b in zip(before, td3.actor.parameters()))
    # Targets trail their networks: soft updates, not copies.
    online = torch.cat([p.flatten() for p in td3.critic.parameters()])
    target = torch.cat([p.flatten() for p in td3.critic_target.parameters()])
    assert 0 < (online - target).abs().max() < 1


@pytest.mark.slow  # trains on two ranks, grows, exports and validates: an end-to-end run
def test_td3_trains_resumes_exports_and_validates_through_the_run_command(artifacts: Path) -> None:
    take = ("--robot", "h1_2", "--motion", "dance2_subject4", "--profile", "smoke", "--nproc", "2")
    sets = (
        "train.algorithm=td3",
        "train.td3.learning_starts=4",
        "train.td3.batch_size=64",
        "validate.render.enabled=false",
    )
    short = cli("run", *take, "--until", "train", "--set", *sets, "train.iterations=3")
    assert short.returncode == 0, short.stderr
    assert "TD3 h1_2: 3/3" in short.stderr
    grown = cli("run", *take, "--resume", "--set", *sets, "train.iterations=5")
    assert grown.returncode == 0, grown.stderr
    assert "continuing the 3-iteration run" in grown.stderr
    runs = sorted((artifacts / "train" / "h1_2" / "dance2_subject4").iterdir(), key=lambda p: p.stat().st_mtime)
    folder = runs[-1]
    rows = read_training_log(folder)
    assert [row["iteration"] for row in rows] == [1, 2, 3, 4, 5]
    # Learning starts once the buffer holds 4 steps (the first iteration collects 4 of each env);
    # from then on every update changes the weights, and both ranks hold the same ones after it.
    assert all(row["loss_critic"] > 0 for row in rows[1:])
    digests = [row["rank_weights"] for row in rows]
    assert all(len(pair) == 2 and pair[0] == pair[1] for pair in digests)
    assert len({pair[0] for pair in digests[1:]}) == 4
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["params"]["algorithm"] == "td3"
    assert manifest["metrics"]["samples"] == 5 * 8 * 4 * 2  # iterations x envs x steps x ranks
    checkpoint = torch.load(checkpoints_by_iteration(folder)[5], weights_only=False)
    assert {"critic_target_state_dict", "actor_optimizer_state_dict"} <= set(checkpoint["algorithm"])
    first, second = checkpoint["ranks"]
    assert first["env"]["rng"] != second["env"]["rng"]
    (validate,) = (artifacts / "validate" / "h1_2" / "dance2_subject4").iterdir()
    report = json.loads((validate / "report.json").read_text())
    assert report["checkpoint"]["iteration"] == 5
    assert report["nominal"]["policy"]["fixed_grid"]["rollouts"] == 23


@pytest.mark.parametrize(
    ("sets", "message"),
    [
        (("train.algorithm=sac",), "parameter 'train.algorithm' must be one of ppo, td3, got 'sac'"),
        (("train.algorithm=td3", "train.td3.noise_std_min=0.5"), "must be at most noise_std_max (0.2), got 0.5"),
    ],
)
def test_a_td3_setting_out_of_range_is_one_line(sets: tuple[str, ...], message: str, artifacts: Path) -> None:
    result = cli("plan", "--robot", "h1_2", "--motion", "dance2_subject4", "--set", *sets)
    assert result.returncode == 2
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith("error: ") and message in line
