"""Training: resume continues bit-for-bit; smoke runs of the whole DAG up to `train` for each robot."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import PROJECT, ReferenceSeeds, check_smoke_training_and_export, cli, h1_2_dance_env

from rd_pipeline.api.workspace import continued_runs, training_seconds, training_seconds_per_run
from rd_pipeline.artifacts.stage import build_params
from rd_pipeline.env.config import EnvConfig
from rd_pipeline.env.mdp.rewards import GROUPS
from rd_pipeline.errors import PipelineError
from rd_pipeline.params import parse_assignments
from rd_pipeline.stages import REGISTRY
from rd_pipeline.training.log import checkpoint_iteration, intact_checkpoints, read_training_log
from rd_pipeline.training.ppo import build_ppo
from rd_pipeline.training.ppo_config import PpoConfig
from rd_pipeline.training.runner import Segments, clip_segments
from rd_pipeline.training.trainer import load_checkpoint, train

INTERRUPTED_ITERATIONS = 12
"""The interrupted run's length: interrupted at its third checkpoint, it has nine left to continue
(each takes seconds with its scoring, so the interrupt never comes after the end)."""


def _setup(seed: int = 3, config: EnvConfig = EnvConfig(num_envs=4, threads=2)):
    torch.manual_seed(seed)
    env = h1_2_dance_env(config, seed)
    ppo = build_ppo(env.get_observations(), env.num_envs, env.num_actions, len(GROUPS), PpoConfig(steps_per_env=6))
    return env, ppo


@pytest.mark.slow
def test_resume_continues_bit_for_bit(tmp_path: Path) -> None:
    env, ppo = _setup()
    (tmp_path / "a").mkdir()
    train(env, ppo, iterations=3, out_dir=tmp_path / "a", checkpoint_every=1)
    straight = {k: v.clone() for k, v in ppo.actor.state_dict().items()}
    resumed_env, resumed_ppo = _setup()
    (tmp_path / "b").mkdir()
    # As if the run had been interrupted after logging iteration 3 but saving only checkpoint 1.
    (tmp_path / "b" / "training_log.jsonl").write_text((tmp_path / "a" / "training_log.jsonl").read_text())
    start = load_checkpoint(tmp_path / "a" / "checkpoints" / "model_1.pt", resumed_ppo, resumed_env)
    assert start == 1
    train(resumed_env, resumed_ppo, iterations=3, out_dir=tmp_path / "b", checkpoint_every=1, start_iteration=start)
    for name, value in resumed_ppo.actor.state_dict().items():
        assert torch.equal(value, straight[name]), name
    straight_log = read_training_log(tmp_path / "a")
    assert [row["iteration"] for row in straight_log] == [1, 2, 3]
    assert all(np.isfinite(row["reward"]) for row in straight_log)
    assert [row["iteration"] for row in read_training_log(tmp_path / "b")] == [1, 2, 3]


def test_zero_action_environment_tracks_and_terminates() -> None:
    env, _ = _setup()
    lengths = []
    time_outs = 0
    for _ in range(60):
        _, reward, dones, extras = env.step(torch.zeros(env.num_envs, env.num_actions))
        assert reward.shape == (4, len(GROUPS)) and torch.isfinite(reward).all()
        lengths += extras["episode_length"].tolist()
        time_outs += int(extras["time_outs"].sum())
    # Zero outputs hold the arms at the default pose while the reference dances: every world
    # fails within a second, by motion-far or tilt, not by reaching the take's end.
    assert len(lengths) >= 8 and time_outs == 0
    assert 1 <= np.mean(lengths) < 40


def test_a_clip_keeps_the_whole_segments_inside_it_and_refuses_one_without_any() -> None:
    segments = Segments(np.array([0, 50, 100]), np.array([50, 50, 30]), np.array([0.2, 0.3, 0.5]))
    inside = clip_segments(segments, 40, 130, fps=50.0)
    assert inside.starts.tolist() == [10, 60] and inside.lengths.tolist() == [50, 30]
    assert inside.weights.tolist() == [0.3, 0.5]
    with pytest.raises(PipelineError) as error:
        clip_segments(segments, 25, 80, fps=50.0)
    assert str(error.value) == (
        "train.clip 0.5:1.6 s holds no whole segment of the sampling prior (segments of 1 s from the take's start): widen it"
    )


def test_the_keypoint_rewards_track_the_torso_and_both_hands() -> None:
    env, _ = _setup()
    tracked = env.robot.config.tracking_bodies
    keypoints = [tracked[i] for i in env.term_context.keypoints]
    assert keypoints == ["torso_link", "left_wrist_yaw_link", "right_wrist_yaw_link"]


@pytest.mark.slow
def test_a_reward_weight_and_a_termination_threshold_set_on_the_command_line_change_key_and_behaviour(
    artifacts: Path,
) -> None:
    changes = {
        "default": (),
        "weight": ("train.env.rewards.body_pos.weight=3.0",),
        "limit": ("train.env.terminations.orientation_limit_rad=0.05",),
    }
    keys = {}
    for label, sets in changes.items():
        result = cli(
            "status", "--robot", "g1", "--motion", "dance1_subject2", "--json", *(("--set", *sets) if sets else ())
        )
        assert result.returncode == 0, result.stderr
        stages = json.loads(result.stdout)["pipelines"][0]["stages"]
        keys[label] = {row["stage"]: row["key"] for row in stages}
    assert keys["default"]["retarget"] == keys["weight"]["retarget"] == keys["limit"]["retarget"]
    assert len({keys[label]["train"] for label in changes}) == 3

    stage = next(s for s in REGISTRY if s.name == "train")
    configs = {
        label: build_params(stage, parse_assignments(sets, ["train"]).get("train", {})).env
        for label, sets in changes.items()
    }
    configs = {label: replace(config, num_envs=4, threads=2) for label, config in configs.items()}
    assert configs["weight"].rewards.body_pos.weight == 3.0
    rollouts = {}
    for label, config in configs.items():
        env, _ = _setup(config=config)
        terms: list[float] = []
        lengths = []
        compute = env.rewards.compute

        def recorded(*args, compute=compute, terms=terms):
            result = compute(*args)
            terms.append(float(result[1]["body_pos"].mean()))
            return result

        env.rewards.compute = recorded
        for _ in range(30):
            _, _, _, extras = env.step(torch.zeros(env.num_envs, env.num_actions))
            lengths += extras["episode_length"].tolist()
        rollouts[label] = (np.array(terms), lengths)
        env.close()
    # Same physics, same draws: only the term's weight differs, 3.0 against 2.0.
    default_terms, default_lengths = rollouts["default"]
    assert np.allclose(rollouts["weight"][0], 1.5 * default_terms, rtol=1e-5)
    # A 0.05 rad tilt limit ends episodes at once; the default lets them run.
    assert len(rollouts["limit"][1]) > len(default_lengths)
    assert np.mean(rollouts["limit"][1]) < np.mean(default_lengths or [30])


@pytest.mark.slow
def test_smoke_profile_runs_the_dag_to_export(artifacts: Path, reference_seeds: ReferenceSeeds) -> None:
    """H1 to export (G1 and H1-2 go on to validate in test_export, with the same checks)."""
    reference_seeds.into(artifacts, "h1", "dance1_subject1")
    result = cli("run", "--robot", "h1", "--motion", "dance1_subject1", "--until", "export", "--profile", "smoke")
    assert result.returncode == 0, result.stderr
    check_smoke_training_and_export(artifacts, "h1", "dance1_subject1")


@pytest.mark.slow
def test_an_interrupted_training_is_continued_by_the_same_command(artifacts: Path) -> None:
    import os
    import signal
    import subprocess
    import sys
    import time

    from conftest import PROJECT

    args = [
        "run",
        "--robot",
        "h1_2",
        "--motion",
        "dance2_subject4",
        "--until",
        "train",
        "--profile",
        "smoke",
        "--set",
        f"train.iterations={INTERRUPTED_ITERATIONS}",
        "train.checkpoint_every=1",
    ]
    process = subprocess.Popen(
        [sys.executable, "-m", "rd_pipeline", *args],
        cwd=PROJECT,
        env=os.environ.copy(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    folder = artifacts / "train" / "h1_2" / "dance2_subject4"
    deadline = time.time() + 300
    while not list(folder.glob(".work-*/checkpoints/model_3.pt")) and time.time() < deadline:
        time.sleep(0.05)
    process.send_signal(signal.SIGINT)
    _, said = process.communicate(timeout=120)
    assert process.returncode == 130
    (work,) = folder.glob(".work-*")
    assert said.strip().splitlines()[-1] == (
        f"interrupted: no partial artifact was kept; train kept its progress in {work}; "
        "the same command continues from it (--force starts over)"
    )
    # The interrupt may land between a checkpoint's bytes and its seal: that one is damaged, and
    # the run goes on from the newest sealed one.
    intact, damaged = intact_checkpoints(work)
    assert intact is not None and len(damaged) <= 1
    saved = checkpoint_iteration(intact)
    assert 2 <= saved < INTERRUPTED_ITERATIONS and not [p for p in folder.iterdir() if not p.name.startswith(".")]
    status = json.loads(cli("status", *args[1:5], "--profile", "smoke", "--set", *args[-2:], "--json").stdout)
    (train,) = [row for row in status["pipelines"][0]["stages"] if row["stage"] == "train"]
    assert train["state"] == "resumable" and str(work) in train["reason"]
    result = cli(*args)  # no --resume: the kept checkpoints are continued, not thrown away
    assert result.returncode == 0, result.stderr
    assert f"continuing the interrupted run from model_{saved}.pt" in result.stderr
    for path in damaged:
        assert f"{path.name} is damaged (its save did not finish (no seal))" in result.stderr
    counts = [int(n) for n in re.findall(rf"PPO h1_2: (\d+)/{INTERRUPTED_ITERATIONS}", result.stderr)]
    assert counts and min(counts) > saved  # the progress counts on from the checkpoint
    (done,) = [p for p in folder.iterdir() if not p.name.startswith(".")]
    logged = [row["iteration"] for row in read_training_log(done)]
    # iterations logged after the last checkpoint are not repeated
    assert logged == list(range(1, INTERRUPTED_ITERATIONS + 1))
    assert not list(folder.glob(".work-*"))  # moved into the artifact


@pytest.mark.usefixtures("g1_dance_store")
@pytest.mark.slow
def test_a_longer_run_with_resume_continues_the_shorter_one_bit_for_bit(artifacts: Path, tmp_path: Path) -> None:
    """`--resume` with more iterations than a finished run continues that run; the result equals the
    longer run made from scratch, and the shorter artifact stays as it was."""
    import shutil

    import torch

    args = ["run", "--robot", "g1", "--motion", "dance1_subject2", "--until", "train", "--profile", "smoke"]
    assert cli(*args, "--set", "train.iterations=2", "train.checkpoint_every=1").returncode == 0
    folder = artifacts / "train" / "g1" / "dance1_subject2"
    (short,) = [p for p in folder.iterdir() if not p.name.startswith(".")]
    longer = cli(*args, "--resume", "--set", "train.iterations=4", "train.checkpoint_every=1")
    assert longer.returncode == 0, longer.stderr
    assert f"continuing the 2-iteration run {short.name}" in longer.stderr
    (grown,) = [p for p in folder.iterdir() if not p.name.startswith(".") and p != short]
    assert continued_runs(grown) == [short, grown]
    per_run = training_seconds_per_run(grown)
    assert list(per_run) == [short.name, grown.name]
    # the grown log carries the shorter run's rows, so its time is counted from them
    assert per_run[short.name] == pytest.approx(sum(row["seconds"] for row in read_training_log(short)))
    assert training_seconds(grown) == pytest.approx(sum(per_run.values()))
    durations = [json.loads((run / "manifest.json").read_text())["duration_s"] for run in (short, grown)]
    assert 0 < training_seconds(grown) < sum(durations)  # start-up and scoring are not iterations
    # with the shorter run gone from the store, its iterations' time stays with the oldest run left
    gone = shutil.copytree(grown, tmp_path / "grown")
    assert continued_runs(gone) == [gone]
    assert training_seconds_per_run(gone) == {grown.name: pytest.approx(training_seconds(grown))}
    with pytest.raises(PipelineError, match="no manifest.json; not a finished artifact"):
        continued_runs(tmp_path)
    _check_training_hours_script(grown, per_run, tmp_path)
    scratch = cli(*args, "--force", "--set", "train.iterations=4", "train.checkpoint_every=1")
    assert scratch.returncode == 0 and "continuing" not in scratch.stderr
    assert sorted(p.name for p in (short / "checkpoints").iterdir()) == ["model_1.pt", "model_2.pt"]
    timing = ("seconds", "samples_per_s")
    strip = lambda rows: [{k: v for k, v in row.items() if k not in timing} for row in rows]
    assert [row["iteration"] for row in read_training_log(tmp_path / "grown")] == [1, 2, 3, 4]
    metrics = lambda run: json.loads((run / "manifest.json").read_text())["metrics"]
    assert metrics(tmp_path / "grown")["continued_from"] == short.name
    assert metrics(grown)["continued_from"] is None
    assert strip(read_training_log(tmp_path / "grown")) == strip(read_training_log(grown))
    a = torch.load(tmp_path / "grown" / "checkpoints" / "model_4.pt", weights_only=False)
    b = torch.load(grown / "checkpoints" / "model_4.pt", weights_only=False)
    for name, value in a["algorithm"]["actor_state_dict"].items():
        assert torch.equal(value, b["algorithm"]["actor_state_dict"][name]), name
    assert a["ranks"][0]["env"]["rng"] == b["ranks"][0]["env"]["rng"]


def _check_training_hours_script(grown: Path, per_run: dict[str, float], tmp_path: Path) -> None:
    """`scripts/training_hours.py --into` puts the log's hours into a result file an older commit's
    bench wrote, where its `wall_h` stood, and says which commit counted them."""
    script = [sys.executable, "-m", "scripts.training_hours"]
    result = tmp_path / "result.json"
    result.write_text(json.dumps({"samples": 4, "wall_h": 9.0, "commit": "d23062d"}))
    hours = subprocess.run([*script, str(grown), "--into", str(result)], capture_output=True, text=True, cwd=PROJECT)
    assert hours.returncode == 0, hours.stderr
    written = json.loads(result.read_text())
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=PROJECT)
    assert list(written) == [
        "samples",
        "wall_h",
        "wall_h_at_median_iteration",
        "wall_h_per_run",
        "commit",
        "hours_commit",
    ]
    assert written["wall_h"] == round(training_seconds(grown) / 3600, 3)
    assert written["wall_h_per_run"] == {key: round(seconds / 3600, 3) for key, seconds in per_run.items()}
    assert written["commit"] == "d23062d" and written["hours_commit"] == head.stdout.strip()
    result.write_text("[1, 2]")
    refused = subprocess.run([*script, str(grown), "--into", str(result)], capture_output=True, text=True)
    assert refused.returncode == 1
    assert refused.stderr == f"error: {result}: not a JSON result file (a list, not an object)\n"
    assert result.read_text() == "[1, 2]"


def test_a_torn_training_log_is_refused_naming_its_file_and_line(tmp_path: Path) -> None:
    """A log cut mid-row (a machine lost while writing) is one line of error, not a traceback."""
    (tmp_path / "training_log.jsonl").write_text('{"iteration": 1, "seconds": 0.8}\n{"iteration": 2, "seco')
    with pytest.raises(PipelineError, match=f"{tmp_path / 'training_log.jsonl'}: line 2 is not a JSON row"):
        read_training_log(tmp_path)
