"""The content-addressed DAG runner: keys, cache hits, selection, forced reruns, atomic writes."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import PROJECT, cli, start_cli

from rd_pipeline import paths
from rd_pipeline.artifacts.keys import artifact_key
from rd_pipeline.artifacts.plan import Pipeline
from rd_pipeline.artifacts.runner import execute
from rd_pipeline.artifacts.sources import resolve_source
from rd_pipeline.artifacts.store import ArtifactStore
from rd_pipeline.errors import PipelineError
from rd_pipeline.stages import REGISTRY, stage_names


def _pipeline(robot: str, motion: str, values: dict | None = None, source: str | None = None) -> Pipeline:
    return Pipeline(REGISTRY, robot, motion, resolve_source(robot, motion, source), values or {})


@pytest.mark.offline
def test_key_is_canonical_and_sensitive() -> None:
    base = artifact_key("parse", 1, {"a": 1.0, "b": "x"}, {}, {"bvh": "00"})
    assert base == artifact_key("parse", 1, {"b": "x", "a": 1.0}, {}, {"bvh": "00"})
    assert len(base) == 12 and int(base, 16) >= 0
    assert base != artifact_key("parse", 2, {"a": 1.0, "b": "x"}, {}, {"bvh": "00"})
    assert base != artifact_key("parse", 1, {"a": 1.5, "b": "x"}, {}, {"bvh": "00"})
    assert base != artifact_key("parse", 1, {"a": 1.0, "b": "x"}, {"up": "k"}, {"bvh": "00"})
    assert base != artifact_key("parse", 1, {"a": 1.0, "b": "x"}, {}, {"bvh": "01"})


def test_source_choice(monkeypatch: pytest.MonkeyPatch) -> None:
    assert resolve_source("g1", "dance1_subject2", None) == "bvh"
    assert resolve_source("h1_2", "dance2_subject4", None) == "csv"
    assert resolve_source("g1", "dance1_subject2", "csv") == "csv"
    # Each source has its own head stages; everything downstream is shared.
    assert [s.name for s in _pipeline("g1", "dance1_subject2").chain()] == [n for n in stage_names() if n != "import"]
    assert [s.name for s in _pipeline("h1_2", "dance2_subject4").chain()] == [
        n for n in stage_names() if n not in ("parse", "retarget")
    ]
    with pytest.raises(PipelineError, match=r"no data for motion 'dance9_subject1'"):
        resolve_source("g1", "dance9_subject1", None)
    # A forced source the take lacks names the missing file and the sources it does have.
    bvh = paths.bvh_path("dance2_subject4")
    lacks = f"--source bvh: {bvh} not found; 'dance2_subject4' has: csv:g1, csv:h1, csv:h1_2"
    with pytest.raises(PipelineError, match=f"^{re.escape(lacks)}$"):
        resolve_source("h1_2", "dance2_subject4", "bvh")
    csv = paths.csv_path("g1", "fallAndGetUp1_subject1")
    with pytest.raises(PipelineError, match=f"^{re.escape(f'--source csv: {csv} not found')}; .* has: bvh$"):
        resolve_source("g1", "fallAndGetUp1_subject1", "csv")


def test_cache_hit_does_no_work_and_force_redoes_it(artifacts: Path) -> None:
    store = ArtifactStore(artifacts)
    pipeline = _pipeline("g1", "dance1_subject2")
    (first,) = execute(pipeline, store, (None, "parse", None))
    assert not first.cached and (first.path / "manifest.json").is_file()
    manifest = json.loads((first.path / "manifest.json").read_text())
    assert manifest["stage"] == "parse" and manifest["key"] == first.key and manifest["robot"] is None
    assert manifest["metrics"]["frames"] == 3945 and manifest["duration_s"] > 0
    assert list(manifest["inputs"].values()) == ["4f15d0b1caac72f9e58745f5ab9183d7dc051dd6fcdc4e1bd90af128b8cfab4d"]
    stamp = (first.path / "human_motion.npz").stat().st_mtime_ns
    (second,) = execute(pipeline, store, (None, "parse", None))
    assert second.cached and second.key == first.key
    assert (first.path / "human_motion.npz").stat().st_mtime_ns == stamp
    (forced,) = execute(pipeline, store, (None, "parse", None), force=True)
    assert not forced.cached and forced.key == first.key
    assert (first.path / "human_motion.npz").stat().st_mtime_ns != stamp
    assert [p.name for p in (artifacts / "parse" / "dance1_subject2").iterdir()] == [first.key]


def test_params_change_the_key_and_the_old_artifact_turns_stale(artifacts: Path) -> None:
    store = ArtifactStore(artifacts)
    (old,) = execute(_pipeline("h1", "dance2_subject1"), store, (None, "import", None))
    changed = _pipeline("h1", "dance2_subject1", {"import": {"interpolation": "linear"}})
    from rd_pipeline.artifacts.status import stage_status

    row = stage_status(changed, store)[0]
    assert row["stage"] == "import" and row["state"] == "stale" and row["other_keys"] == [old.key]
    (new,) = execute(changed, store, (None, "import", None))
    assert new.key != old.key and not new.cached


def test_selection_errors() -> None:
    pipeline = _pipeline("h1_2", "dance2_subject4")
    known = ", ".join(stage_names())
    with pytest.raises(PipelineError, match=rf"^--until: unknown stage 'no_such_stage' \(stages: {known}\)$"):
        pipeline.select(None, "no_such_stage", None)
    with pytest.raises(
        PipelineError, match=r"^--only: stage 'parse' is not in the csv pipeline for h1_2/dance2_subject4"
    ):
        pipeline.select(None, None, "parse")


def test_bad_parameter_is_named(artifacts: Path) -> None:
    result = cli("run", "--robot", "h1", "--motion", "dance2_subject1", "--set", "import.fps=fast")
    assert result.returncode == 2
    assert "error: parameter 'import.fps' must be a number, got 'fast'" in result.stderr
    result = cli("run", "--robot", "h1", "--motion", "dance2_subject1", "--set", "import.speed=2")
    assert "error: unknown parameter 'import.speed'" in result.stderr
    assert not (artifacts / "import").exists()


def test_tuple_parameters_from_set() -> None:
    from rd_pipeline.artifacts.stage import build_params
    from rd_pipeline.stages import REGISTRY

    validate, train = (next(s for s in REGISTRY if s.name == n) for n in ("validate", "train"))
    assert build_params(validate, {"randomized.seeds": "[0, 1, 2]"}).randomized.seeds == (0, 1, 2)
    assert build_params(train, {"env.randomization.push_interval_s": "4,8"}).env.randomization.push_interval_s == (
        4.0,
        8.0,
    )
    with pytest.raises(
        PipelineError, match=r"^parameter 'train.env.randomization.push_interval_s' must be a number, got 'x'$"
    ):
        build_params(train, {"env.randomization.push_interval_s": "4,x"})


def test_unknown_robot_and_motion_are_one_line(artifacts: Path) -> None:
    result = cli("run", "--robot", "t800", "--motion", "dance1_subject2")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith("error: unknown robot 't800'")
    result = cli("run", "--robot", "g1", "--motion", "tango")
    assert result.returncode == 2
    line = result.stderr.strip()
    assert line.startswith("error: no data for motion 'tango'") and len(line.splitlines()) == 1
    hint = (
        "`rd-pipeline fetch-lafan` downloads LAFAN1's BVH files, or point RD_LAFAN_DIR (BVH files), "
        "RD_RETARGETED_DIR (dataset CSVs) and RD_ROBOT_ASSETS (robot models) at the data, as variables "
        "or in rd-pipeline.toml"
    )
    assert line.endswith(hint)


@pytest.mark.slow
def test_cli_cache_hit_and_status_json(artifacts: Path) -> None:
    first = cli("run", "--robot", "g1", "--motion", "dance1_subject2", "--until", "parse")
    assert first.returncode == 0, first.stderr
    second = cli("run", "--robot", "g1", "--motion", "dance1_subject2", "--until", "parse")
    assert second.returncode == 0 and "cached parse" in second.stderr and "no work" in second.stderr
    assert cli("stage", "import", "--robot", "h1_2", "--motion", "dance2_subject4").returncode == 0
    status = json.loads(cli("status", "--json").stdout)
    states = {
        (p["robot"], p["motion"], s["stage"]): s["state"]
        for p in status["pipelines"]
        for s in p["stages"]
        if s["state"] != "missing"
    }
    # parse is robot-independent: its artifact belongs to no robot.
    assert states == {(None, "dance1_subject2", "parse"): "cached", ("h1_2", "dance2_subject4", "import"): "cached"}
    # Piped, the table keeps whole paths on one line.
    table = cli("status").stdout
    path = next(s["path"] for p in status["pipelines"] for s in p["stages"] if s["state"] == "cached")
    assert any(path in line for line in table.splitlines())


@pytest.mark.slow
def test_killed_stage_leaves_no_artifact(artifacts: Path) -> None:
    folder = artifacts / "import" / "h1_2" / "dance2_subject4"
    process = subprocess.Popen(
        [sys.executable, "-m", "rd_pipeline", "stage", "import", "--robot", "h1_2", "--motion", "dance2_subject4"],
        cwd=PROJECT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=os.environ.copy(),
    )
    deadline = time.time() + 60
    while not list(folder.glob(".tmp-*")) and time.time() < deadline:
        time.sleep(0.02)
    time.sleep(0.5)  # well inside the ~2 s of work
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert process.returncode == -signal.SIGKILL
    assert len(list(folder.glob(".tmp-*"))) == 1
    assert ArtifactStore(artifacts).keys("import", "h1_2", "dance2_subject4") == []
    status = json.loads(cli("status", "--robot", "h1_2", "--motion", "dance2_subject4", "--json").stdout)
    assert status["pipelines"][0]["stages"][0]["state"] == "missing"
    # Another key's, of a process this machine cannot see (one sharing the store), is not this run's to clean.
    other = folder / ".tmp-0123456789ab-999999-0badc0de"
    other.mkdir()
    rerun = cli("stage", "import", "--robot", "h1_2", "--motion", "dance2_subject4")
    assert rerun.returncode == 0 and "run    import" in rerun.stderr
    assert list(folder.glob(".tmp-*")) == [other]  # the key's abandoned folder was cleaned up
    assert len(ArtifactStore(artifacts).keys("import", "h1_2", "dance2_subject4")) == 1


def test_interrupt_removes_the_partial_artifact(artifacts: Path) -> None:
    # Retargeting runs for seconds, so the interrupt lands inside the stage's work, not after it.
    folder = artifacts / "retarget" / "g1" / "dance1_subject1"
    process = start_cli("run", "--robot", "g1", "--motion", "dance1_subject1", "--until", "retarget")
    deadline = time.time() + 120
    while not list(folder.glob(".tmp-*")) and time.time() < deadline:
        time.sleep(0.02)
    time.sleep(1.0)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130 and "Traceback" not in stderr, stderr
    assert "interrupted: no partial artifact was kept" in stderr
    assert list(folder.iterdir()) == []
