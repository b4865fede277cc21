"""`studies/action_scale.py` rolls a trained checkpoint out with its outputs scaled: at scale 1 from
start 0 it survives exactly as long as the training scored that checkpoint, and a checkpoint
whose outputs are pushed far off ends sooner at scale 1 than at scale 0, as zero output does
with the actor's noise widened far."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from conftest import PROJECT

from rd_pipeline.api import workspace
from rd_pipeline.training.log import read_training_log

SETS = ("train.checkpoint_every=1",)
CLIP = "11:13"


def _scale(out: Path, *extra: str) -> subprocess.CompletedProcess:
    script = [sys.executable, "-m", "studies.action_scale"]
    args = ["--profile", "smoke", "--clip", CLIP, "--iterations", "2", "--set", *SETS, "--out", str(out), *extra]
    return subprocess.run([*script, *args], capture_output=True, text=True, cwd=PROJECT)


def _survival(out: Path, checkpoint: int, *joints: str) -> dict[str, list[float]]:
    extra = ("--joints", *joints) if joints else ()
    # As many starts as train scores from: the same randomized worlds, so the same score.
    measured = _scale(out, "--checkpoint", str(checkpoint), "--scales", "1", "0", "--starts", "8", *extra)
    assert measured.returncode == 0, measured.stderr
    result = json.loads(out.with_suffix(".json").read_text())
    assert result["checkpoint"] == checkpoint
    assert result["start_s"] == [0.0, 0.24, 0.48, 0.72, 0.96, 1.2, 1.44, 1.68]
    if joints:
        assert result["scaled_joints"] == [f"{side}_elbow_joint" for side in ("left", "right")]
    return result["survival_s"]


@pytest.mark.slow
@pytest.mark.usefixtures("g1_dance_store")
def test_scaled_outputs_reproduce_the_logged_score_and_see_a_harmful_policy(artifacts: Path, tmp_path: Path) -> None:
    overrides = (f"train.clip={CLIP}", "train.iterations=2", *SETS)
    plan = workspace.plan("g1", "dance1_subject2", "smoke", overrides=overrides)
    workspace.run(plan, until="train")
    train = workspace.required_artifact(plan, "train")
    logged = {row["iteration"]: row["start_zero_s"] for row in read_training_log(train)}
    trained = _survival(tmp_path / "trained", 1)
    assert trained["1.0"][0] == logged[1]
    # Checkpoint 2's outputs pushed 8 action units off (2 rad on a joint at scale 0.25).
    path = workspace.training_checkpoints(train)[2]
    state = torch.load(path, weights_only=False)
    state["algorithm"]["actor_state_dict"]["mlp.6.bias"] += 8.0
    torch.save(state, path)
    harmful = _survival(tmp_path / "harmful", 2)
    assert harmful["0.0"] == trained["0.0"]  # zero outputs, whatever the weights
    assert all(bad < zero for bad, zero in zip(harmful["1.0"], harmful["0.0"]))
    # Zeroing the elbows alone leaves the other joints pushed off: the rollouts still end early.
    elbows_zeroed = _survival(tmp_path / "elbows", 2, "*_elbow_joint")
    assert elbows_zeroed["1.0"] == harmful["1.0"]
    assert all(bad < zero for bad, zero in zip(elbows_zeroed["0.0"], harmful["0.0"]))
    # Checkpoint 1's noise widened to 8 action units: zero output plus that noise ends sooner.
    noisy_path = workspace.training_checkpoints(train)[1]
    state = torch.load(noisy_path, weights_only=False)
    state["algorithm"]["actor_state_dict"]["distribution.std_param"].fill_(8.0)
    torch.save(state, noisy_path)
    noisy = _scale(tmp_path / "noisy", "--checkpoint", "1", "--scales", "0", "--starts", "4", "--noise-draws", "2")
    assert noisy.returncode == 0, noisy.stderr
    result = json.loads((tmp_path / "noisy.json").read_text())
    assert (result["noise_draws"], set(result["noise_std"])) == (2, {8.0})
    assert all(shaken < still for shaken, still in zip(result["survival_s"]["0.0"], trained["0.0"]))
    table = (tmp_path / "noisy.md").read_text()
    assert "With the actor's noise (std 8.00-8.00 action units by joint), median of 2 draws per start." in table
    none = _scale(tmp_path / "none", "--joints", "*_tail_joint")
    assert none.returncode == 1
    assert none.stderr.strip().startswith(
        "error: --joints *_tail_joint matches no policy joint (left_hip_pitch_joint, "
    )
    negative = _scale(tmp_path / "negative", "--noise-draws", "-1")
    assert negative.returncode == 1
    assert negative.stderr.strip() == "error: --noise-draws -1: give 0 (no noise) or more draws"
    missing = _scale(tmp_path / "missing", "--checkpoint", "3")
    assert missing.returncode == 1
    assert missing.stderr.strip() == f"error: {train} holds no checkpoint 3"
