"""What every benchmark and study shares: which code a result came from, how a result is
written, and how many hours a training took.

Run the benchmarks, studies and operations scripts as modules from the repository root
(`python -m bench.retarget`), so each can import this one."""

from __future__ import annotations

import json
import statistics
import subprocess
from pathlib import Path
from typing import Any

from rd_pipeline.api.workspace import training_log, training_seconds, training_seconds_per_run


def head_commit(checkout: Path = Path(__file__).parent) -> str:
    """The commit of `checkout` (by default the one the bench runs from; an installed copy has
    none: "unknown")."""
    git = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=checkout)
    return git.stdout.strip() or "unknown"


def write_result(out: Path, result: Any, table: str) -> None:
    """Write `<out>.json` (the result) and `<out>.md` (its table), and print the table."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(result, indent=2) + "\n")
    out.with_suffix(".md").write_text(table)
    print(table)


def training_hours(train: Path) -> dict[str, Any]:
    """The hours as they passed (with any pause or sharing of the machine within the iterations),
    at the median iteration's pace (the machine to itself), and per run in the store."""
    per_run = training_seconds_per_run(train)
    seconds = [row["seconds"] for row in training_log(train)]
    if not seconds:
        raise ValueError(f"{train}: its training log has no iterations")
    return {
        "wall_h": round(training_seconds(train) / 3600, 3),
        "wall_h_at_median_iteration": round(len(seconds) * statistics.median(seconds) / 3600, 3),
        "wall_h_per_run": {key: round(run_seconds / 3600, 3) for key, run_seconds in per_run.items()},
    }
