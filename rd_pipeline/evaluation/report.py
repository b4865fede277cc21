"""Validation reports: `report.json` (SPEC metric names), `report.md` (paper-shaped tables) and plots."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from rd_pipeline.evaluation.metrics import DRIFT_BINS, ERROR_METRICS, SUCCESS_THRESHOLDS_S
from rd_pipeline.evaluation.validation_report import REPORT_JSON

REPORT_MD = "report.md"
RECORDING_FILE = "sim2sim.rrd"
DRIFT_PLOT = "drift.png"
SURVIVAL_PLOT = "survival_per_start.png"
CONTROLLERS = ("policy", "zero_action")
"""Report columns: the exported policy and the reference fed straight to PD."""


def write_json(report: dict, out_dir: Path) -> None:
    (out_dir / REPORT_JSON).write_text(json.dumps(report, indent=2) + "\n")


def _cell(value: object, digits: int = 2) -> str:
    if value is None:
        return "–"
    if isinstance(value, dict):  # a seed reduction
        if value.get("mean") is None:
            return "–"
        return f"{value['mean']:.{digits}f}" + (
            f" ± {value['ci95']:.{digits}f}" if value.get("ci95") is not None else ""
        )
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def write_markdown(report: dict, out_dir: Path) -> None:
    """Tables shaped like the paper's: survival protocols, then tracking errors, then drift."""
    sections = [
        _title(report),
        _pictures(report),
        _protocols_table(report),
        _tracked_table(report),
        _survival_table(report),
        _endings_table(report),
        _tracking_table(report),
        _drift_table(report),
        _definitions(report),
    ]
    text = "\n\n".join("\n".join(lines) for lines in sections)
    (out_dir / REPORT_MD).write_text(text + "\n")


def _title(report: dict) -> list[str]:
    reference = report["reference"]
    rates = report["rates"]
    return [
        f"# Sim2sim validation: {report['robot']} / {report['motion']}",
        "",
        f"Policy `{report['policy_key']}` on reference `{reference['key']}` frames "
        f"{reference['start_frame']}–{reference['end_frame']} "
        f"({reference['duration_s']:.1f} s), deploy loop at "
        f"{rates['control_hz']:.0f} Hz policy / {rates['physics_hz']:.0f} Hz physics.",
        "",
        f"Checkpoint: {_checkpoint_line(report.get('checkpoint', {}))}",
    ]


def _checkpoint_line(checkpoint: dict) -> str:
    if not checkpoint:
        return "not recorded by this export."
    return f"iteration {checkpoint['iteration']}, chosen by {checkpoint['rule']}."


def _pictures(report: dict) -> list[str]:
    pictures = report.get("pictures", {})
    lines = ["## Pictures", ""]
    if pictures.get("filmstrip"):
        lines += [f"![start-zero rollout beside its reference]({pictures['filmstrip']})", ""]
        lines.append(f"Video: [{pictures['video']}]({pictures['video']}). ")
    elif pictures.get("skipped"):
        lines.append(f"No filmstrip or video: {pictures['skipped']}. ")
    lines[-1] += f"Plots: [survival per start]({SURVIVAL_PLOT}), [drift]({DRIFT_PLOT})."
    if report.get("recording"):
        lines[-1] += f" Recording: [{report['recording']}]({report['recording']}) (`rerun {report['recording']}`)."
    return lines


def _protocols_table(report: dict) -> list[str]:
    lines = [
        "## Protocols (mean ± 95% CI)",
        "",
        "| protocol | physics | controller | start-zero (s) | completion % | mean survival (s) | tracked % |",
        "|---|---|---|---|---|---|---|",
    ]
    for protocol, figures in report["protocols"].items():
        runs = f"{figures['runs']} × {figures['rollouts_per_run']} rollouts"
        for name in CONTROLLERS:
            row = figures[name]
            cells = [_cell(row[key]) for key in ("start_zero_s", "completion_pct", "mean_survival_s", "tracked_pct")]
            lines.append(f"| {protocol} | {figures['physics']} ({runs}) | {name} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "CIs are Student-t over seeds where a protocol has several, else over the grid's starts (a "
        "single start-zero rollout has none).",
    ]
    return lines


def _tracked_table(report: dict) -> list[str]:
    tracking = report["tracking"]
    tolerance = tracking["tolerance"]
    lines = [
        "## Tracking second by second (nominal, from the clip's start)",
        "",
        f"A step is tracked when the mean joint error is under {tolerance['joint_rad']:g} rad and the "
        f"mean pelvis-relative body error under {tolerance['body_m']:g} m. Share of the clip tracked: "
        + ", ".join(f"{name} {tracking['start_zero_tracked_pct'][name]:.1f} %" for name in CONTROLLERS)
        + ".",
        "",
        "| second | " + " | ".join(f"{n} joint (rad) | {n} body (m) | {n} tracked %" for n in CONTROLLERS) + " |",
        "|---|" + "---|---|---|" * len(CONTROLLERS),
    ]
    rows = list(zip(*(tracking["per_second"][name] for name in CONTROLLERS)))
    alive = [any(second["joint_rad"] is not None for second in row) for row in rows]
    shown = max((k for k, a in enumerate(alive) if a), default=0) + 2
    for row in rows[:shown]:
        cells = []
        for second in row:
            cells += [_cell(second["joint_rad"], 3), _cell(second["body_m"], 3), _cell(second["tracked_pct"], 0)]
        lines.append(f"| {row[0]['second']} | " + " | ".join(cells) + " |")
    if len(rows) > shown:
        lines += ["", f"Seconds {shown} to {len(rows) - 1}: both rollouts had ended."]
    return lines


def _definitions(report: dict) -> list[str]:
    return [
        "## Definitions",
        "",
        "- start-zero: seconds survived from the clip's first frame.",
        "- fixed grid: one rollout from every start on a grid along the clip; completion is the share "
        "that reach the clip's end, mean survival their mean seconds survived.",
        "- failure: pelvis tilted past the orientation limit, a termination body beyond the motion-far "
        "distance from its reference, or a body other than the feet on the floor.",
        "- tracked %: per start, the steps tracked (see above) over the steps it could have lasted "
        "(to the clip's end), averaged over the starts.",
        "- E_g_mpbpe / E_mpbpe: mean body position error in the world / relative to the pelvis (mm); "
        "E_mpjpe: mean joint position error (mrad); E_mpjve, E_mpbve: their velocities.",
        "- zero action: the reference fed straight to the PD controllers, the baseline every figure stands beside.",
        "- randomized: the paper's domain randomization and sensor noise, drawn per rollout from "
        "validation's own seeds; other physics: the same model on another friction cone and timestep "
        "(its row names them and the integrator).",
    ]


def _survival_table(report: dict) -> list[str]:
    lines = [
        "## Survival",
        "",
        "| controller | start-zero survival (s) | completion % | mean survival (s) | "
        + " | ".join(f"success@{t}s %" for t in SUCCESS_THRESHOLDS_S)
        + " |",
        "|---|---|---|---|" + "---|" * len(SUCCESS_THRESHOLDS_S),
    ]
    for name in CONTROLLERS:
        grid = report["nominal"][name]["fixed_grid"]
        zero = report["nominal"][name]["start_zero"]
        cells = [_cell(zero["mean_survival_s"]), _cell(grid["completion_pct"]), _cell(grid["mean_survival_s"])]
        cells += [_cell(grid[f"success_{t}s_pct"]) for t in SUCCESS_THRESHOLDS_S]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    ceiling = report["nominal"]["policy"]["fixed_grid"]["mean_survival_ceiling_s"]
    lines += [
        "",
        f"A start can last at most what is left of the clip: the mean survival can be at most {ceiling:.2f} s.",
    ]
    return lines


def _endings_table(report: dict) -> list[str]:
    lines = [
        "## What ended the rollouts (fixed grid)",
        "",
        "| controller | failure at the last step: rollouts |",
        "|---|---|",
    ]
    for name in CONTROLLERS:
        ended = Counter(cause or "the clip's end" for cause in report["nominal"][name]["per_start"]["ended_by"])
        counts = sorted(ended.items(), key=lambda item: (-item[1], item[0]))
        lines.append(f"| {name} | " + ", ".join(f"{cause}: {count}" for cause, count in counts) + " |")
    lines += ["", "`far B`: termination body B was the farthest from its reference, beyond the motion-far distance."]
    return lines


def _tracking_table(report: dict) -> list[str]:
    lines = [
        "## Tracking error (fixed grid, every step survived)",
        "",
        "| controller | " + " | ".join(ERROR_METRICS) + " |",
        "|---|" + "---|" * len(ERROR_METRICS),
    ]
    for name in CONTROLLERS:
        grid = report["nominal"][name]["fixed_grid"]
        lines.append(f"| {name} | " + " | ".join(_cell(grid[m]) for m in ERROR_METRICS) + " |")
    lines += ["", "Units: E_g_mpbpe, E_mpbpe mm; E_mpjpe mrad; E_mpjve mrad/s; E_mpbve mm/s."]
    return lines


def _drift_table(report: dict) -> list[str]:
    lines = [
        f"## Drift (E_g_mpbpe per relative time bin, mean and bootstrap 95% CI, {DRIFT_BINS} bins)",
        "",
        "| controller | " + " | ".join(f"bin {b + 1}" for b in range(DRIFT_BINS)) + " |",
        "|---|" + "---|" * DRIFT_BINS,
    ]
    for name in CONTROLLERS:
        bins = report["nominal"][name]["drift"]
        lines.append(f"| {name} | " + " | ".join(_drift_cell(b) for b in bins) + " |")
    return lines


def _drift_cell(drift_bin: dict) -> str:
    """Mean [CI] of one drift bin; a dash where no rollout lasted long enough to fill it."""
    if drift_bin["mean"] is None:
        return "–"
    return f"{drift_bin['mean']:.1f} [{drift_bin['ci_low']:.1f}, {drift_bin['ci_high']:.1f}]"


def plot_report(report: dict, out_dir: Path) -> None:
    """Drift with its CI band, and survival per fixed-grid start, policy beside the zero-action baseline."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colors = {"policy": "tab:blue", "zero_action": "tab:gray"}
    fig, ax = plt.subplots(figsize=(5.5, 3.2))
    for name in CONTROLLERS:
        bins = [b for b in report["nominal"][name]["drift"] if b["mean"] is not None]
        x = [b["bin"] + 1 for b in bins]
        ax.plot(x, [b["mean"] for b in bins], marker="o", color=colors[name], label=name)
        ax.fill_between(x, [b["ci_low"] for b in bins], [b["ci_high"] for b in bins], color=colors[name], alpha=0.2)
    ax.set_xlabel("relative time bin")
    ax.set_ylabel("E_g_mpbpe (mm)")
    ax.set_title(f"{_who(report)}\nbody position error over the rollout, nominal physics", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / DRIFT_PLOT, dpi=110)
    plt.close(fig)

    # Points, not bars: a few seconds of survival at starts spread over minutes of take.
    fig, ax = plt.subplots(figsize=(6.5, 3.4))
    for name in CONTROLLERS:
        per_start = report["nominal"][name]["per_start"]
        ax.plot(per_start["start_s"], per_start["survival_s"], "o-", color=colors[name], label=name, ms=4, lw=1)
    most = report["nominal"]["policy"]["per_start"]
    longest = max(max(report["nominal"][name]["per_start"]["survival_s"]) for name in CONTROLLERS)
    ax.plot(most["start_s"], most["most_s"], ":", color="black", label="to the clip's end")
    ax.set_ylim(0, 1.25 * max(longest, 0.1))
    ax.set_xlabel("start time (s)")
    ax.set_ylabel("survival (s)")
    ax.set_title(f"{_who(report)}\nsurvival from each fixed-grid start, nominal physics", fontsize=9)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(out_dir / SURVIVAL_PLOT, dpi=110)
    plt.close(fig)


def _who(report: dict) -> str:
    """The plots' first title line: robot, motion and policy."""
    return f"{report['robot']} {report['motion']}, policy {report['policy_key']}"
