"""`studies/checkpoint_curve.py` lays checkpoints chosen by iteration in iteration order, each with
its training-model score beside its mesh figures, and refuses a checkpoint the run never scored."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from conftest import PROJECT

SCRIPT = [sys.executable, "-m", "studies.checkpoint_curve"]
CHECKPOINTS = PROJECT / "studies" / "results" / "dance_window_h1_2_visited_checkpoints"


def test_checkpoints_read_in_iteration_order_with_both_models_figures(tmp_path: Path) -> None:
    given = [CHECKPOINTS / "checkpoint_36000.json", CHECKPOINTS / "checkpoint_35000.json"]
    out = tmp_path / "curve"
    written = subprocess.run(
        [*SCRIPT, *map(str, given), "--out", str(out)], capture_output=True, text=True, cwd=PROJECT
    )
    assert written.returncode == 0, written.stderr
    peak, last = json.loads(out.with_suffix(".json").read_text())
    # 35000 is one of the training model's 5.5 s peaks; on the mesh it lasts 2.98 s
    assert (peak["checkpoint"], peak["samples_m"], peak["training_model_start_zero_s"]) == (35000, 107.5, 5.5)
    assert (peak["start_zero_s"], peak["mean_survival_s"], peak["zero_action_mean_survival_s"]) == (2.98, 1.11, 0.62)
    assert (last["checkpoint"], last["samples_m"], last["training_model_start_zero_s"]) == (36000, 110.6, 2.02)
    assert (last["start_zero_s"], last["mean_survival_s"]) == (2.46, 1.03)
    assert out.with_suffix(".png").stat().st_size > 0
    table = out.with_suffix(".md").read_text().splitlines()
    assert table[2] == (
        "| 35000 | 107.5 M | 5.50 | 2.98 (0.62) | 1.11 (0.62; 5.48) "
        "| 2.98, 0.86, 1.26, 2.42, 1.48, 0.56, 0.76, 0.24, 0.26, 0.26 |"
    )


def test_a_checkpoint_the_run_never_scored_is_one_line(tmp_path: Path) -> None:
    result = json.loads((CHECKPOINTS / "checkpoint_36000.json").read_text())
    result["exported_checkpoint"] = 36050
    odd = tmp_path / "checkpoint_36050.json"
    odd.write_text(json.dumps(result))
    refused = subprocess.run(
        [*SCRIPT, str(odd), "--out", str(tmp_path / "curve")], capture_output=True, text=True, cwd=PROJECT
    )
    assert refused.returncode == 1
    assert refused.stderr.strip().splitlines() == [
        f"error: {odd}: checkpoint 36050 is not among the run's scored checkpoints"
    ]
    assert not (tmp_path / "curve.json").exists()
