"""`studies/dance_window_stages.py` lays scored stages side by side as their result files say, and a
result file that is not there is one line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from conftest import PROJECT

SCRIPT = [sys.executable, "-m", "studies.dance_window_stages"]
RESULTS = PROJECT / "studies" / "results"


def test_the_h1_2_stages_read_as_their_result_files_say(tmp_path: Path) -> None:
    stages = [RESULTS / "dance_window_h1_2_median_24000.json", RESULTS / "dance_window_h1_2_visited_8000.json"]
    out = tmp_path / "stages"
    written = subprocess.run(
        [*SCRIPT, *map(str, stages), "--out", str(out)], capture_output=True, text=True, cwd=PROJECT
    )
    assert written.returncode == 0, written.stderr
    start_credit, visited = json.loads(out.with_suffix(".json").read_text())
    assert (start_credit["failure_credit"], start_credit["samples_m"], start_credit["exported_checkpoint"]) == (
        "start",
        73.7,
        21000,
    )
    assert (start_credit["start_zero_s"], start_credit["mean_survival_s"]) == (3.26, 1.06)
    # zero action's grid: 0.62, 0.58, 0.60, 0.80, 0.74, 0.48, 0.54, 0.66, 0.62, 0.56
    assert start_credit["zero_action_mean_survival_s"] == 0.62
    assert (start_credit["starts_outlasting_zero_action"], start_credit["starts"]) == (5, 10)
    assert (visited["failure_credit"], visited["samples_m"], visited["starts_outlasting_zero_action"]) == (
        "visited",
        24.6,
        4,
    )
    table = out.with_suffix(".md").read_text().splitlines()
    assert len(table) == 4
    assert table[2].startswith("| dance_window_h1_2_median_24000.json | start | 73.7 M | 6.23 | 21000 | 3.26 (0.62) |")


def test_a_missing_result_is_one_line(tmp_path: Path) -> None:
    missing = tmp_path / "gone.json"
    refused = subprocess.run(
        [*SCRIPT, str(missing), "--out", str(tmp_path / "stages")], capture_output=True, text=True, cwd=PROJECT
    )
    assert refused.returncode == 1
    assert refused.stderr.strip().splitlines() == [f"error: [Errno 2] No such file or directory: '{missing}'"]
    assert not (tmp_path / "stages.json").exists()
