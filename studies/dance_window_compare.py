"""Benchmark: dance-window runs side by side, by samples and by PPO updates.

    python -m studies.dance_window_compare [RESULT.json ...] [--out studies/results/dance_window_compare]

Reads result files written by `studies/dance_window.py` (default: the CPU run and both GPU leases)
and writes `OUT.png` (the training model's start-zero survival at each checkpoint against samples
and against iterations) and `OUT.json` (per run: where start-zero first beat zero action's, and the
best reached within equal sample budgets).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

RESULTS = Path(__file__).parent / "results"
DEFAULT_RUNS = ("dance_window.json", "dance_window_gpu_lease1.json", "dance_window_gpu.json")
BUDGETS_M = (10, 20, 30, 50, 100)
"""Sample budgets (millions) at which the runs are compared."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="*", type=Path, default=[RESULTS / name for name in DEFAULT_RUNS])
    parser.add_argument("--out", type=Path, default=RESULTS / "dance_window_compare")
    args = parser.parse_args()
    runs = {path.stem: json.loads(path.read_text()) for path in args.results}
    summary = {name: _summary(run) for name, run in runs.items()}
    args.out.with_suffix(".json").write_text(json.dumps(summary, indent=2) + "\n")
    _plot(runs, args.out.with_suffix(".png"))
    print(json.dumps(summary, indent=2))


def _summary(run: dict[str, Any]) -> dict[str, Any]:
    checkpoints = run["checkpoints"]
    samples_per_iteration = run["samples"] / checkpoints[-1]["iteration"]
    zero_action = run["zero_action_start_zero_s"]
    beating = [c for c in checkpoints if c["training_model_start_zero_s"] > zero_action]
    best_within = {}
    for budget in BUDGETS_M:
        within = [c["training_model_start_zero_s"] for c in checkpoints if c["samples"] <= budget * 1e6]
        if checkpoints[-1]["samples"] >= budget * 1e6 and within:
            best_within[f"{budget}M"] = max(within)
    return {
        "profile": run["profile"],
        "num_envs": run["options"]["num_envs"],
        "samples_per_iteration": round(samples_per_iteration),
        "samples": run["samples"],
        "iterations": checkpoints[-1]["iteration"],
        "first_beats_zero_action_at_samples": beating[0]["samples"] if beating else None,
        "first_beats_zero_action_at_iteration": beating[0]["iteration"] if beating else None,
        "best_training_model_start_zero_s_within": best_within,
        "exported_mesh_start_zero_s": run["start_zero_s"],
        "zero_action_start_zero_s": zero_action,
    }


def _plot(runs: dict[str, dict[str, Any]], path: Path) -> None:
    figure, (by_samples, by_updates) = plt.subplots(1, 2, figsize=(12, 4.2))
    for name, run in runs.items():
        checkpoints = run["checkpoints"]
        survival = [c["training_model_start_zero_s"] for c in checkpoints]
        label = f"{name} ({run['profile']}, {run['options']['num_envs']} envs)"
        by_samples.semilogx([c["samples"] for c in checkpoints], survival, "o-", ms=2, lw=1, label=label)
        by_updates.semilogx([c["iteration"] for c in checkpoints], survival, "o-", ms=2, lw=1, label=label)
    zero_action = next(iter(runs.values()))["zero_action_start_zero_s"]
    for axis, xlabel in ((by_samples, "PPO samples"), (by_updates, "PPO iterations (updates)")):
        axis.axhline(zero_action, color="gray", ls="--", label="zero action")
        axis.set(xlabel=xlabel, ylabel="start-zero survival, training model (s)")
        axis.legend(fontsize=7)
    run = next(iter(runs.values()))
    figure.suptitle(f"{run['robot']} {run['motion']} {run['clip']} s")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


if __name__ == "__main__":
    main()
