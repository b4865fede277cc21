"""Training: resume continues bit-for-bit; smoke runs of the whole DAG up to `train` for each robot."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import RETARGETED_DIR, cli

from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.rl.env import TrackingEnv
from rd_pipeline.rl.env_config import EnvConfig
from rd_pipeline.rl.ppo import PpoConfig, build_ppo
from rd_pipeline.rl.rewards import GROUPS
from rd_pipeline.rl.trainer import load_checkpoint, train
from rd_pipeline.robots import load_robot
from rd_pipeline.sampling.sampler import SamplerConfig, SegmentSampler
from rd_pipeline.sampling.segments import segment_bounds


def _setup(seed: int = 3):
    torch.manual_seed(seed)
    robot = load_robot("h1_2")
    reference = import_retargeted_csv(RETARGETED_DIR / "h1_2" / "dance2_subject4.csv", robot, 30.0, 50.0, "cubic",
                                      ContactThresholds()).reference
    starts, lengths = segment_bounds(reference.n_frames, 50.0, 1.0, 0.25)
    sampler = SegmentSampler(SamplerConfig(), torch.ones(len(starts)), seed=seed)
    env = TrackingEnv(robot, reference, sampler, starts, lengths, EnvConfig(num_envs=4, threads=2), seed=seed)
    ppo = build_ppo(env.get_observations(), env.num_envs, env.num_actions, len(GROUPS), PpoConfig(steps_per_env=6))
    return env, ppo


def test_resume_continues_bit_for_bit(tmp_path: Path) -> None:
    env, ppo = _setup()
    (tmp_path / "a").mkdir()
    train(env, ppo, iterations=3, out_dir=tmp_path / "a", checkpoint_every=1)
    straight = {k: v.clone() for k, v in ppo.actor.state_dict().items()}
    resumed_env, resumed_ppo = _setup()
    (tmp_path / "b").mkdir()
    start = load_checkpoint(tmp_path / "a" / "checkpoints" / "model_1.pt", resumed_ppo, resumed_env)
    assert start == 1
    train(resumed_env, resumed_ppo, iterations=3, out_dir=tmp_path / "b", checkpoint_every=1, start_iteration=start)
    for name, value in resumed_ppo.actor.state_dict().items():
        assert torch.equal(value, straight[name]), name
    log = [json.loads(line) for line in (tmp_path / "a" / "training_log.jsonl").read_text().splitlines()]
    assert [row["iteration"] for row in log] == [1, 2, 3] and all(np.isfinite(row["reward"]) for row in log)


def test_zero_action_environment_tracks_and_terminates() -> None:
    env, _ = _setup()
    lengths = []
    for _ in range(60):
        _, reward, dones, extras = env.step(torch.zeros(env.num_envs, env.num_actions))
        assert reward.shape == (4, len(GROUPS)) and torch.isfinite(reward).all()
        lengths += extras["episode_length"].tolist()
    # The reference fed straight to PD falls within seconds: episodes end by motion-far / tilt.
    assert lengths and 1 <= np.mean(lengths) < 60


@pytest.mark.parametrize(("robot", "motion"), [("g1", "dance1_subject2"), ("h1", "dance1_subject1"),
                                                ("h1_2", "dance2_subject4")])
def test_smoke_profile_runs_the_dag_to_train(robot: str, motion: str, artifacts: Path) -> None:
    result = cli("run", "--robot", robot, "--motion", motion, "--until", "train", "--profile", "smoke")
    assert result.returncode == 0, result.stderr
    (folder,) = (artifacts / "train" / robot / motion).iterdir()
    assert (folder / "learning_curve.png").is_file() and (folder / "checkpoints" / "model_2.pt").is_file()
    metrics = json.loads((folder / "manifest.json").read_text())["metrics"]
    assert metrics["iterations"] == 2 and metrics["num_envs"] == 8


def test_cli_resume_continues_an_interrupted_training(artifacts: Path) -> None:
    import os
    import signal
    import subprocess
    import sys
    import time

    from conftest import PROJECT

    args = ["run", "--robot", "h1_2", "--motion", "dance2_subject4", "--until", "train", "--profile", "smoke",
            "--set", "train.iterations=30", "train.checkpoint_every=1"]
    process = subprocess.Popen([sys.executable, "-m", "rd_pipeline", *args], cwd=PROJECT, env=os.environ.copy(),
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    folder = artifacts / "train" / "h1_2" / "dance2_subject4"
    deadline = time.time() + 300
    while not list(folder.glob(".work-*/checkpoints/model_3.pt")) and time.time() < deadline:
        time.sleep(0.05)
    process.send_signal(signal.SIGINT)
    assert process.wait(timeout=120) == 130
    (work,) = folder.glob(".work-*")
    saved = max(int(p.stem.split("_")[1]) for p in (work / "checkpoints").glob("model_*.pt"))
    assert 3 <= saved < 30 and not [p for p in folder.iterdir() if not p.name.startswith(".")]
    result = cli(*args, "--resume")
    assert result.returncode == 0, result.stderr
    assert f"resuming from model_{saved}.pt" in result.stderr
    (done,) = [p for p in folder.iterdir() if not p.name.startswith(".")]
    log = [json.loads(line)["iteration"] for line in (done / "training_log.jsonl").read_text().splitlines()]
    assert log[-1] == 30 and log[:3] == [1, 2, 3]
    assert not list(folder.glob(".work-*"))  # moved into the artifact
