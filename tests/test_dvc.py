"""The DVC pipeline mirrors the registry and reproduces a stage in a temporary project."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from conftest import LAFAN_DIR, PROJECT

from rd_pipeline.stages import stage_names


def test_dvc_stages_are_the_registry() -> None:
    dvc = yaml.safe_load((PROJECT / "dvc.yaml").read_text())
    assert list(dvc["stages"]) == stage_names()
    params = yaml.safe_load((PROJECT / "params.yaml").read_text())
    assert set(params["stages"]) <= set(stage_names())
    for name, stage in dvc["stages"].items():
        assert stage["cmd"].startswith(f"rd-pipeline stage {name} ")
        assert f"stages.{name}" in stage["params"]


@pytest.mark.slow  # the whole smoke DAG through dvc: an end-to-end run
def test_dvc_repro_runs_the_smoke_dag(tmp_path: Path) -> None:
    dvc = shutil.which("dvc", path=str(Path(sys.executable).parent)) or shutil.which("dvc")
    if dvc is None:
        pytest.skip("the dvc extra is not installed (CI installs it)")
    shutil.copy(PROJECT / "dvc.yaml", tmp_path / "dvc.yaml")
    params = yaml.safe_load((PROJECT / "params.yaml").read_text())
    params["stages"]["validate"]["render"] = {"enabled": False}  # test_export looks at the pictures
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    (tmp_path / "robots").symlink_to(PROJECT / "robots")  # dvc.yaml lists the robot configs as dependencies
    (tmp_path / "raw_lafan").mkdir()
    (tmp_path / "raw_lafan" / "dance1_subject2.bvh").symlink_to(LAFAN_DIR / "dance1_subject2.bvh")
    env = {k: v for k, v in os.environ.items() if k not in ("RD_LAFAN_DIR", "RD_ARTIFACTS")}
    env["PATH"] = f"{Path(sys.executable).parent}:{env['PATH']}"
    run = lambda *args: subprocess.run([dvc, *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert run("init", "--no-scm").returncode == 0
    # The smoke profile (params.yaml) through the whole DAG for G1 on dance1_subject2 (matrix item motion1).
    result = run("repro", "validate@g1-motion1")
    assert result.returncode == 0, result.stdout + result.stderr
    for stage in ("retarget", "stats", "prior", "train", "export", "validate"):
        (artifact,) = (tmp_path / "artifacts" / stage / "g1" / "dance1_subject2").iterdir()
        assert (artifact / "manifest.json").is_file(), stage
    (report,) = (tmp_path / "artifacts" / "validate" / "g1" / "dance1_subject2").glob("*/report.json")
    assert '"zero_action"' in report.read_text()
    lock = yaml.safe_load((tmp_path / "dvc.lock").read_text())
    assert {"parse@dance1_subject2", "train@g1-motion1", "validate@g1-motion1"} <= set(lock["stages"])
    again = run("repro", "validate@g1-motion1")
    assert again.returncode == 0 and "didn't change, skipping" in again.stdout
