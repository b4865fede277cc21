"""Benchmark table: the scored stages of dance-window runs, one row each, as their result files say.

    python -m studies.dance_window_stages RESULT.json ... [--out studies/results/dance_window_h1_2_stages]

Reads result files written by `studies/dance_window.py` and writes `OUT.json` and `OUT.md`: per
stage its samples, hours at the median iteration, exported checkpoint, mesh start-zero and
fixed-grid mean survival beside zero action's, how many fixed-grid starts outlast zero action,
and the survival from each start. A run's stages read down in the order given.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

from bench.common import write_result

RESULTS = Path(__file__).parent / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, default=RESULTS / "dance_window_stages")
    args = parser.parse_args()
    try:
        rows = [stage_row(path) for path in args.results]
    except (OSError, KeyError, ValueError) as exc:
        sys.exit(f"error: {exc}")
    write_result(args.out, rows, _table(rows))


def stage_row(path: Path) -> dict[str, Any]:
    """One scored stage: the figures a reader compares across stages and runs."""
    result = json.loads(path.read_text())
    policy = result["fixed_grid_survival_s"]
    zero = result["fixed_grid_zero_action_survival_s"]
    return {
        "result": path.name,
        "robot": result["robot"],
        "clip": result["clip"],
        "failure_credit": result["options"]["failure_credit"],
        "commit": result["commit"],
        "samples_m": round(result["samples"] / 1e6, 1),
        "hours_at_median_iteration": result.get("wall_h_at_median_iteration"),
        "exported_checkpoint": result["exported_checkpoint"],
        **survival_fields(result),
        "starts_outlasting_zero_action": sum(ours > theirs for ours, theirs in zip(policy, zero, strict=True)),
        "starts": len(policy),
        "fixed_grid_survival_s": policy,
    }


def survival_fields(result: dict[str, Any]) -> dict[str, Any]:
    """A result file's mesh start-zero and fixed-grid mean beside zero action's, as the tables read them."""
    zero = result["fixed_grid_zero_action_survival_s"]
    return {
        "start_zero_s": result["start_zero_s"],
        "zero_action_start_zero_s": result["zero_action_start_zero_s"],
        "mean_survival_s": round(result["mean_survival_s"], 2),
        "zero_action_mean_survival_s": round(statistics.mean(zero), 2),
        "mean_survival_ceiling_s": result["mean_survival_ceiling_s"],
    }


def survival_cells(row: dict[str, Any]) -> list[str]:
    """The table cells of `survival_fields` and of the survival from each fixed-grid start."""
    return [
        f"{row['start_zero_s']:.2f} ({row['zero_action_start_zero_s']:.2f})",
        f"{row['mean_survival_s']:.2f} ({row['zero_action_mean_survival_s']:.2f}; {row['mean_survival_ceiling_s']:.2f})",
        ", ".join(f"{value:.2f}" for value in row["fixed_grid_survival_s"]),
    ]


def _table(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| result | credit | samples | h | checkpoint | start-zero (zero action) | grid mean (zero action; most) "
        "| starts > zero action | per start (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        hours = row["hours_at_median_iteration"]
        start_zero, grid_mean, per_start = survival_cells(row)
        cells = [
            row["result"],
            row["failure_credit"],
            f"{row['samples_m']} M",
            "" if hours is None else f"{hours:.2f}",
            str(row["exported_checkpoint"]),
            start_zero,
            grid_mean,
            f"{row['starts_outlasting_zero_action']} of {row['starts']}",
            per_start,
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
