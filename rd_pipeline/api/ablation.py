"""Ablations: sweeps whose variants are the arms of one of the paper's studies, reduced to its tables.

Each trial's validation report gives one number per metric; a seed's number is the mean over the
sweep's robots and motions; a table cell is the mean and 95% Student-t half-width over seeds.
"""

from __future__ import annotations

import json
from pathlib import Path

from rd_pipeline.api.sweeps import TrialResult
from rd_pipeline.env.mdp.actions import RESIDUAL_PRESETS
from rd_pipeline.evaluation.metrics import ERROR_METRICS, t_interval

STUDIES: dict[str, dict[str, tuple[str, ...]]] = {
    "residual": {mode: (f"train.env.actions.mode={mode}",) for mode in RESIDUAL_PRESETS},
    "sampler": {mode: (f"train.sampler.mode={mode}",) for mode in ("uniform", "distribution", "failure", "combined")},
}
"""Study -> arm -> `--set` overrides."""

METRICS: dict[str, tuple[str, ...]] = {
    "residual": ERROR_METRICS,
    "sampler": (
        "completion_pct",
        "mean_survival_s",
        "success_10s_pct",
        "success_20s_pct",
        "success_30s_pct",
        "start_zero_survival_s",
    ),
}
"""The columns of each study's table (the paper's table shapes), from the nominal policy report."""


def _value(report: dict, metric: str) -> float | None:
    policy = report["nominal"]["policy"]
    if metric == "start_zero_survival_s":
        return policy["start_zero"]["mean_survival_s"]
    return policy["fixed_grid"][metric]


def ablation_table(study: str, arms: tuple[str, ...], results: list[TrialResult]) -> dict:
    """{arm: {metric: {mean, ci95, n}}} over seeds, from the trials' `report.json`."""
    table: dict[str, dict] = {}
    for arm in arms:
        per_seed: dict[int, list[dict]] = {}
        for r in results:
            if r.trial.variant == arm and r.report:
                per_seed.setdefault(r.trial.seed, []).append(json.loads(Path(r.report).read_text()))
        row = {}
        for metric in METRICS[study]:
            seeds: list[float | None] = []
            for reports in per_seed.values():
                values = [v for v in (_value(rep, metric) for rep in reports) if v is not None]
                seeds.append(sum(values) / len(values) if values else None)
            row[metric] = t_interval(seeds)
        table[arm] = row
    return table


def format_cell(cell: dict) -> str:
    """`mean ± ci95` of a `t_interval` cell (`mean` alone for one seed, `–` for none)."""
    if cell["mean"] is None:
        return "–"
    return f"{cell['mean']:.2f}" + (f" ± {cell['ci95']:.2f}" if cell["ci95"] is not None else "")


def write_ablation(study: str, table: dict, results: list[TrialResult], out_dir: Path) -> Path:
    """`ablation.json` and `ablation.md` (arms x metrics, mean ± 95% CI over seeds)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    failed = [r.trial.label for r in results if not r.ok]
    (out_dir / "ablation.json").write_text(
        json.dumps({"study": study, "table": table, "failed_trials": failed}, indent=2) + "\n"
    )
    metrics = METRICS[study]
    lines = [
        f"# Ablation: {study}",
        "",
        (
            "Mean ± 95% Student-t half-width over seeds (n = seeds with a report); "
            "each seed is the mean over the sweep's robots and motions."
        ),
        "",
        "| arm | " + " | ".join(metrics) + " | n |",
        "|---|" + "---|" * (len(metrics) + 1),
    ]
    for arm, row in table.items():
        cells = [format_cell(row[m]) for m in metrics]
        lines.append(f"| {arm} | " + " | ".join(cells) + f" | {max(row[m]['n'] for m in metrics)} |")
    if failed:
        lines += ["", "Failed trials: " + ", ".join(failed)]
    path = out_dir / "ablation.md"
    path.write_text("\n".join(lines) + "\n")
    return path
