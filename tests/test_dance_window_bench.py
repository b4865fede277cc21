"""`studies/dance_window.py` trains, exports and validates a window of a take from the source it is
told to use, and writes the result file issue 31 asks for; a source the take lacks is one line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import LAFAN_DIR, PROJECT

SCRIPT = [sys.executable, "-m", "studies.dance_window"]


@pytest.mark.slow
def test_a_smoke_window_from_the_dataset_csv_writes_the_result_file(artifacts: Path, tmp_path: Path) -> None:
    out = tmp_path / "window.json"
    args = ["--source", "csv", "--clip", "11:13", "--profile", "smoke", "--iterations", "2", "--out", str(out)]
    measured = subprocess.run([*SCRIPT, *args], capture_output=True, text=True, cwd=PROJECT)
    assert measured.returncode == 0, measured.stderr
    result = json.loads(out.read_text())
    chosen = (result["robot"], result["motion"], result["clip"], result["source"])
    assert chosen == ("g1", "dance1_subject2", "11:13", "csv")
    # smoke: 2 iterations of 8 environments x 8 steps
    assert result["samples"] == 128
    assert [row["iteration"] for row in result["checkpoints"]] == [1, 2]
    assert result["exported_checkpoint"] in (1, 2)
    assert len(result["fixed_grid_start_s"]) == len(result["fixed_grid_survival_s"])
    assert 0.0 < result["start_zero_s"] <= 2.0
    assert result["options"]["num_envs"] == 8
    assert (tmp_path / "window_curve.png").stat().st_size > 0
    assert (tmp_path / "window_sampler_profile.png").stat().st_size > 0


def test_a_source_the_take_lacks_is_one_line_and_no_result(artifacts: Path, tmp_path: Path) -> None:
    out = tmp_path / "window.json"
    args = ["--robot", "h1_2", "--motion", "dance2_subject4", "--source", "bvh", "--clip", "0:2", "--out", str(out)]
    refused = subprocess.run([*SCRIPT, *args], capture_output=True, text=True, cwd=PROJECT)
    assert refused.returncode == 1
    bvh = LAFAN_DIR / "dance2_subject4.bvh"
    has = "'dance2_subject4' has: csv:g1, csv:h1, csv:h1_2"
    assert refused.stderr.strip().splitlines() == [f"error: --source bvh: {bvh} not found; {has}"]
    assert not out.exists()
