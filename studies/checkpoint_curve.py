"""Benchmark curve: a run's checkpoints at fixed iterations, validated on the mesh, against samples.

    python -m studies.checkpoint_curve CHECKPOINT.json ... [--out studies/results/checkpoint_curve]

A stage's exported checkpoint is the best training-model start-zero among those it holds, so a
noisy score picks a lucky checkpoint. This reads result files of checkpoints chosen by iteration
alone (`studies/dance_window.py ... --set export.checkpoint=N`) and writes `OUT.json`, `OUT.md` and
`OUT.png`: per checkpoint its samples, the training model's start-zero when it was scored, and its
mesh start-zero and fixed-grid mean survival beside zero action's.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from bench.common import write_result
from studies.dance_window_stages import survival_cells, survival_fields

RESULTS = Path(__file__).parent / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, default=RESULTS / "checkpoint_curve")
    args = parser.parse_args()
    try:
        rows = sorted((checkpoint_row(path) for path in args.results), key=lambda row: row["checkpoint"])
    except (OSError, KeyError, ValueError) as exc:
        sys.exit(f"error: {exc}")
    write_result(args.out, rows, _table(rows))
    _plot(rows, args.out.with_suffix(".png"))


def checkpoint_row(path: Path) -> dict[str, Any]:
    """One validated checkpoint: when it was trained and what it does on each model."""
    result = json.loads(path.read_text())
    checkpoint = result["exported_checkpoint"]
    scored = {entry["iteration"]: entry for entry in result["checkpoints"]}
    if checkpoint not in scored:
        raise ValueError(f"{path}: checkpoint {checkpoint} is not among the run's scored checkpoints")
    return {
        "result": path.name,
        "checkpoint": checkpoint,
        "samples_m": round(scored[checkpoint]["samples"] / 1e6, 1),
        "training_model_start_zero_s": scored[checkpoint]["training_model_start_zero_s"],
        **survival_fields(result),
        "fixed_grid_survival_s": result["fixed_grid_survival_s"],
    }


def _table(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| checkpoint | samples | training-model start-zero | mesh start-zero (zero action) "
        "| grid mean (zero action; most) | per start (s) |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        cells = [
            str(row["checkpoint"]),
            f"{row['samples_m']} M",
            f"{row['training_model_start_zero_s']:.2f}",
            *survival_cells(row),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _plot(rows: list[dict[str, Any]], path: Path) -> None:
    samples = [row["samples_m"] for row in rows]
    figure, axes = plt.subplots(figsize=(8, 4.5))
    axes.plot(samples, [row["training_model_start_zero_s"] for row in rows], "o:", label="training model, start-zero")
    axes.plot(samples, [row["start_zero_s"] for row in rows], "o-", label="mesh, start-zero")
    axes.plot(samples, [row["mean_survival_s"] for row in rows], "s-", label="mesh, fixed-grid mean")
    axes.axhline(rows[0]["zero_action_start_zero_s"], color="gray", linestyle="--", label="zero action, start-zero")
    axes.axhline(rows[0]["zero_action_mean_survival_s"], color="gray", linestyle=":", label="zero action, grid mean")
    axes.set_xlabel("samples (M)")
    axes.set_ylabel("survival (s)")
    axes.set_title("checkpoints at fixed iterations, validated on the 500 Hz mesh model")
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


if __name__ == "__main__":
    main()
