"""A training restored from a saved state (`scripts/dance_window_state.py`) carries its whole log but
holds only the checkpoints saved since; train chooses among the checkpoints it holds. A
fork of a longer run finishes as the shorter run without training."""

from __future__ import annotations

import gzip
import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import PROJECT

from rd_pipeline.api import workspace
from rd_pipeline.artifacts.store import MANIFEST
from rd_pipeline.training.log import checkpoints_by_iteration, read_training_log

SETS = ("train.checkpoint_every=1",)
CLIP = "11:13"
"""Two seconds: every checkpoint is scored by rolling it out over the clip."""
ROBOT = "g1"
MOTION = "dance1_subject2"


def _plan(iterations: int) -> workspace.Plan:
    overrides = (f"train.clip={CLIP}", f"train.iterations={iterations}", *SETS)
    return workspace.plan(ROBOT, MOTION, "smoke", overrides=overrides, seed=0)


def _state(action: str, iterations: int, state: Path, *extra: str) -> subprocess.CompletedProcess:
    script = [sys.executable, "-m", "scripts.dance_window_state"]
    args = [
        action,
        "--profile",
        "smoke",
        "--clip",
        CLIP,
        "--iterations",
        str(iterations),
        "--set",
        *SETS,
        "--state",
        str(state),
        *extra,
    ]
    return subprocess.run([*script, *args], capture_output=True, text=True, cwd=PROJECT)


def _manifest(plan: workspace.Plan, stage: str) -> dict:
    artifact = plan.store.find(stage, ROBOT, MOTION, plan.stage(stage).key)
    assert artifact is not None
    return json.loads((artifact.path / MANIFEST).read_text())


@pytest.mark.slow
@pytest.mark.usefixtures("g1_dance_store")
def test_a_restored_run_chooses_among_the_checkpoints_it_holds(artifacts: Path, tmp_path: Path) -> None:
    workspace.run(_plan(2), until="train")
    state = tmp_path / "state"
    saved = _state("save", 2, state)
    assert saved.returncode == 0, saved.stderr
    assert sorted(path.name for path in state.iterdir()) == ["model_2.pt", "state.json", "training_log.jsonl.gz"]
    # The saved log's best score is iteration 1's, whose checkpoint the state does not hold.
    packed = state / "training_log.jsonl.gz"
    rows = [json.loads(line) for line in gzip.decompress(packed.read_bytes()).splitlines()]
    rows[0]["start_zero_s"] = 99.0
    packed.write_bytes(gzip.compress("".join(json.dumps(row) + "\n" for row in rows).encode()))
    # Restored beside the shorter run it came from, which a run without `--resume` does not continue.
    restored = _state("restore", 4, state)
    assert restored.returncode == 0, restored.stderr
    grown = _plan(4)
    workspace.run(grown, until="export")
    train = grown.store.find("train", ROBOT, MOTION, grown.stage("train").key)
    assert train is not None
    log = read_training_log(train.path)
    assert [row["iteration"] for row in log] == [1, 2, 3, 4] and log[0]["start_zero_s"] == 99.0
    assert list(checkpoints_by_iteration(train.path)) == [2, 3, 4]
    scores = {row["iteration"]: (row["start_zero_s"], row["completion"]) for row in log[1:]}
    best = max(scores, key=lambda it: (*scores[it], it))
    assert _manifest(grown, "train")["metrics"]["best_checkpoint"] == best
    assert _manifest(grown, "export")["metrics"]["checkpoint_iteration"] == 4  # the last, by iteration


@pytest.mark.slow
@pytest.mark.usefixtures("g1_dance_store")
def test_a_fork_finishes_a_stage_of_a_longer_run_without_training(artifacts: Path, tmp_path: Path) -> None:
    longer = _plan(4)
    workspace.run(longer, until="train")
    stage = _plan(2)
    # What a fork that failed partway leaves beside the work folder, and a start that trained nothing.
    into = stage.store.work_folder("train", ROBOT, MOTION, stage.stage("train").key)
    (into.with_name(f"{into.name}.forking") / "checkpoints").mkdir(parents=True)
    into.mkdir()
    (into / "training_log.jsonl").write_text("")
    forked = _state("fork", 4, tmp_path, "--at", "2")
    assert forked.returncode == 0, forked.stderr
    assert sorted(path.name for path in into.parent.iterdir() if path.name.startswith(into.name)) == [into.name]
    workspace.run(stage, until="train")
    train = stage.store.find("train", ROBOT, MOTION, stage.stage("train").key)
    source = longer.store.find("train", ROBOT, MOTION, longer.stage("train").key)
    assert train is not None and source is not None
    # Its rows are the longer run's, seconds included: nothing was trained again.
    assert read_training_log(train.path) == read_training_log(source.path)[:2]
    held = checkpoints_by_iteration(train.path)
    assert list(held) == [1, 2]
    assert held[2].samefile(checkpoints_by_iteration(source.path)[2])
    again = _state("fork", 4, tmp_path, "--at", "2")
    assert again.returncode == 1
    assert again.stderr.strip() == f"error: train {train.key} (2 iterations) is finished already"
    missing = _state("fork", 4, tmp_path, "--at", "5")
    assert missing.stderr.strip() == f"error: train {source.key} holds no checkpoint 5 in {source.path}"


def test_restore_refuses_a_checkpoint_of_another_train_key(artifacts: Path, tmp_path: Path) -> None:
    state = tmp_path / "state"
    state.mkdir()
    saved = {"robot": ROBOT, "motion": MOTION, "clip": CLIP, "train_key": "614b15e5ee28"}
    saved |= {"iteration": 2, "iterations": 2, "checkpoint": "model_2.pt"}
    (state / "state.json").write_text(json.dumps(saved))
    restored = _state("restore", 4, state)
    key = _plan(2).stage("train").key
    assert restored.returncode == 1
    assert restored.stderr.strip() == (
        f"error: {state / 'state.json'} holds a checkpoint of train 614b15e5ee28, "
        f"but this code and these arguments make train {key}: "
        "restore with the code and arguments that trained it"
    )
    work = _plan(4).store.work_folder("train", ROBOT, MOTION, _plan(4).stage("train").key)
    assert not work.exists()
