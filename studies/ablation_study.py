"""Benchmark: the paper's ablations at CPU scale, with their learning curves.

    python -m studies.ablation_study residual [--arms absolute selective all reference_locked] [--seeds 0 1 2] \
        [--motion dance1_subject2] [--clip 0:10] [--profile cpu] [--set stage.param=value ...]
    python -m studies.ablation_study sampler --clip 0:20 [--seeds 0 1] ...

`residual` is the residual-mask study (the paper's learning-curve figure and Table r5), `sampler`
the resampling ablation (its threshold-success and survival table, plus each arm's sampler profile).
Runs `rd-pipeline ablate <study>` one trial at a time, seed by seed (every arm has its first seed
before any arm has its second), always with `--resume`: a finished trial is cached in the artifact
store and an interrupted training continues from its last checkpoint, so rerunning the same
command continues the study. After every trial it rewrites `<out>.json`, `<out>.md` and
`<out>_curves.png` (default out: `studies/results/<study>_study`) from the artifacts of the trials
finished so far. Validation figures come from each trial's `validate` report (the exported policy on
the full mesh model; each seed's row says which checkpoint export took); a seed's wall time is its
train stage's. The report ends with the paper's
findings judged on the seeds: supported, contradicted or undecided by Welch's 95% interval of the
difference between the two arms.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from rd_pipeline.api.ablation import STUDIES, format_cell
from rd_pipeline.api.sweeps import Trial, trial_artifact
from rd_pipeline.api.workspace import training_seconds
from rd_pipeline.artifacts.store import MANIFEST
from rd_pipeline.evaluation.metrics import ERROR_METRICS, t_interval
from rd_pipeline.evaluation.report import REPORT_JSON
from rd_pipeline.stages.train import PROFILE_FILE
from rd_pipeline.training.log import checkpoints_by_iteration, read_training_log
from studies.findings import (
    PAPER_RESAMPLING,
    PAPER_TABLE_R5,
    RESIDUAL_CLAIMS,
    SAMPLER_CLAIMS,
    Claim,
    judge,
)

ROBOT = "g1"
CURVE_STATISTICS = ("early_episode_length_s", "late_episode_length_s", "late_reward")
"""Per-seed learning-curve statistics: means over the first and over the last `--curve-window` iterations."""
SATURATED_EMA = 0.95
"""A segment whose failure EMA is at least this is saturated: nearly every episode started there fails."""


@dataclass(frozen=True)
class StudySpec:
    """What one ablation runs and reports."""

    title: str
    """Heading of the markdown report."""
    arms: tuple[str, ...]
    """Default arms."""
    seeds: tuple[int, ...]
    """Default seeds."""
    columns: tuple[str, ...]
    """Table columns: start-zero survival, then the nominal policy's fixed-grid figures."""
    paper: dict[str, dict[str, str]]
    """The paper's figures for the same arms, quoted for orientation."""
    paper_caption: str
    """What the quoted figures are."""
    claims: tuple[Claim, ...]
    """The paper's findings this study can judge."""


SPECS = {
    "residual": StudySpec(
        title="Residual study at CPU scale (the paper's Table r5 and learning-curve figure)",
        arms=("absolute", "selective", "all", "reference_locked"),
        seeds=(0, 1, 2),
        columns=("start_zero_s", "completion_pct", "mean_survival_s", *ERROR_METRICS),
        paper=PAPER_TABLE_R5,
        paper_caption="The paper's Table r5 (dance2_subject4, GPU scale; survival in s, errors in mm/mrad), "
        "for orientation only: a different motion and budget.",
        claims=RESIDUAL_CLAIMS,
    ),
    "sampler": StudySpec(
        title="Sampler ablation at CPU scale (the paper's resampling table)",
        arms=("uniform", "distribution", "failure", "combined"),
        seeds=(0, 1),
        columns=(
            "start_zero_s",
            "completion_pct",
            "mean_survival_s",
            "success_10s_pct",
            "success_20s_pct",
            "success_30s_pct",
        ),
        paper=PAPER_RESAMPLING,
        paper_caption="The paper's resampling table (a), threshold success in % (dance2_subject4, GPU scale), "
        "for orientation only: a different motion and budget.",
        claims=SAMPLER_CLAIMS,
    ),
}


def shared_sets(args: argparse.Namespace) -> tuple[str, ...]:
    """The overrides of every trial, in the order `ablate` puts them before the arm's."""
    return (f"train.clip={args.clip}", *args.set)


def trials(args: argparse.Namespace) -> list[Trial]:
    return [
        Trial(ROBOT, args.motion, seed, arm, shared_sets(args) + STUDIES[args.study][arm])
        for seed in args.seeds
        for arm in args.arms
    ]


def run(trial: Trial, args: argparse.Namespace) -> bool:
    command = [
        sys.executable,
        "-m",
        "rd_pipeline",
        "ablate",
        args.study,
        "--robots",
        ROBOT,
        "--motions",
        trial.motion,
        "--seeds",
        str(trial.seed),
        "--arms",
        trial.variant,
        "--profile",
        args.profile,
        "--workers",
        "1",
        "--resume",
        "--set",
        *shared_sets(args),
    ]
    print(f"{trial.label}: running", flush=True)
    return subprocess.run(command, check=False).returncode == 0


def seed_result(trial: Trial, args: argparse.Namespace) -> dict | None:
    """One seed's row, or None while its trial has not finished."""
    train = trial_artifact(trial, args.profile, "train")
    export = trial_artifact(trial, args.profile, "export")
    validate = trial_artifact(trial, args.profile, "validate")
    if train is None or export is None or validate is None:
        return None
    report = json.loads((validate / REPORT_JSON).read_text())["nominal"]["policy"]
    manifest = json.loads((train / MANIFEST).read_text())
    params = manifest["params"]
    row = {
        "seed": trial.seed,
        "start_zero_s": report["start_zero"]["mean_survival_s"],
        **{m: report["fixed_grid"][m] for m in SPECS[args.study].columns[1:]},
        "checkpoint": json.loads((export / MANIFEST).read_text())["metrics"]["checkpoint_iteration"],
        "wall_min": round(training_seconds(train) / 60, 2),
        "samples": params["iterations"] * params["ranks"] * params["env"]["num_envs"] * params["ppo"]["steps_per_env"],
        "train_key": manifest["key"],
        "train_folder": str(train),
    }
    rows = read_training_log(train)
    # Logs of runs resumed before the trainer dropped the rows past the checkpoint repeat them
    # (identically: training is deterministic); each iteration counts once.
    log = list({row["iteration"]: row for row in rows}.values())
    row["curve"] = {
        "iteration": [r["iteration"] for r in log],
        "episode_length_s": [r["episode_length_s"] or 0.0 for r in log],
        "reward": [r["reward"] for r in log],
    }
    window = args.curve_window
    row["early_episode_length_s"] = round(float(np.mean(row["curve"]["episode_length_s"][:window])), 4)
    row["late_episode_length_s"] = round(float(np.mean(row["curve"]["episode_length_s"][-window:])), 4)
    row["late_reward"] = round(float(np.mean(row["curve"]["reward"][-window:])), 4)
    row["failure_ema"] = final_failure_ema(train)
    return row


def final_failure_ema(train: Path) -> list[float]:
    """Rank 0's per-segment failure EMA at the last checkpoint: what its failure prior weighed."""
    last = list(checkpoints_by_iteration(train).values())[-1]
    state = torch.load(last, map_location="cpu", weights_only=False)
    return [round(float(rate), 3) for rate in state["ranks"][0]["sampler"]["failure_rate"]]


def summary(args: argparse.Namespace) -> dict:
    arms = []
    samples = set()
    for arm in args.arms:
        seeds = []
        for trial in trials(args):
            if trial.variant == arm:
                row = seed_result(trial, args)
                if row is not None:
                    seeds.append(row)
                    samples.add(row["samples"])
        columns = (*SPECS[args.study].columns, *CURVE_STATISTICS, "wall_min")
        table = {m: t_interval([s[m] for s in seeds]) for m in columns}
        arms.append({"arm": arm, "seeds": seeds, "table": table})
    by_arm = {arm["arm"]: arm["seeds"] for arm in arms}
    return {
        "study": args.study,
        "robot": ROBOT,
        "clip": f"{args.motion} {args.clip} s",
        "profile": args.profile,
        "sets": list(args.set),
        "samples_per_trial": min(samples) if len(samples) == 1 else sorted(samples),
        "curve_window": args.curve_window,
        "arms": arms,
        "claims": [judge(claim, by_arm) for claim in SPECS[args.study].claims],
    }


def markdown(result: dict) -> str:
    spec = SPECS[result["study"]]
    columns = (*spec.columns, "wall_min")
    lines = [
        f"# {spec.title}",
        "",
        (
            f"{result['robot']}, {result['clip']}, `{result['profile']}` profile, "
            f"{result['samples_per_trial']} samples per trial. Written by `studies/ablation_study.py`."
        ),
    ]
    lines += _arm_table_lines(result, columns)
    lines += _seed_table_lines(result, columns)
    lines += _curve_table_lines(result)
    lines += _claim_table_lines(result)
    lines += failure_ema_lines(result)
    lines += _paper_table_lines(spec, columns)
    return "\n".join(lines) + "\n"


def _table_head(*names: str) -> list[str]:
    return ["| " + " | ".join(names) + " |", "|" + "---|" * len(names)]


def _arm_table_lines(result: dict, columns: tuple[str, ...]) -> list[str]:
    lines = [
        "",
        (
            "Mean ± 95 % Student-t half-width over seeds. start_zero_s: one deterministic rollout from frame 0; "
            "the other columns: the fixed grid of starts (one per second), nominal physics, full mesh model; "
            "wall_min: the train stage's minutes (a grown training adds the run it continued)."
        ),
        "",
        *_table_head("arm", "n", *columns),
    ]
    for arm in result["arms"]:
        cells = " | ".join(format_cell(arm["table"][m]) for m in columns)
        lines.append(f"| {arm['arm']} | {len(arm['seeds'])} | {cells} |")
    return lines


def _seed_table_lines(result: dict, columns: tuple[str, ...]) -> list[str]:
    lines = ["", "Per seed:", "", *_table_head("arm", "seed", *columns)]
    for arm in result["arms"]:
        for seed in arm["seeds"]:
            values = " | ".join(f"{seed[m]}" for m in columns)
            lines.append(f"| {arm['arm']} | {seed['seed']} | {values} |")
    return lines


def _curve_table_lines(result: dict) -> list[str]:
    window = result["curve_window"]
    lines = [
        "",
        f"Learning curves (mean ± 95 % CI over seeds): training episode length over the first and the last "
        f"{window} iterations, and the mean reward per step over the last {window}.",
        "",
        *_table_head("arm", *CURVE_STATISTICS),
    ]
    for arm in result["arms"]:
        cells = " | ".join(format_cell(arm["table"][m]) for m in CURVE_STATISTICS)
        lines.append(f"| {arm['arm']} | {cells} |")
    return lines


def _claim_table_lines(result: dict) -> list[str]:
    lines = [
        "",
        "The paper's findings against these seeds: the difference of the two arms' means with Welch's 95 % "
        "interval, signed so that a positive value favours the finding (for errors: the other arm's minus the "
        "better arm's). Supported when the interval lies above zero, contradicted when below, undecided when "
        "it holds zero.",
        "",
        *_table_head("finding", "metric", "seeds", "difference", "95 % interval", "verdict"),
    ]
    for claim in result["claims"]:
        interval = "–" if claim["low"] is None else f"[{claim['low']}, {claim['high']}]"
        difference = "–" if claim["difference"] is None else f"{claim['difference']}"
        seeds = "/".join(str(n) for n in claim["seeds"])
        lines.append(
            f"| {claim['claim']} | {claim['metric']} | {seeds} | {difference} | {interval} | {claim['verdict']} |"
        )
    return lines


def failure_ema_lines(result: dict) -> list[str]:
    """How much the failure prior had to go on: segments whose failure EMA is saturated at the end
    (no lines where no trial's sampler kept one, as under a uniform sampler)."""
    rows = []
    for arm in result["arms"]:
        for seed in arm["seeds"]:
            ema = np.asarray(seed.get("failure_ema", []))
            if ema.size == 0:
                continue
            saturated = int(np.sum(ema >= SATURATED_EMA))
            rows.append(f"| {arm['arm']} | {seed['seed']} | {ema.size} | {saturated} | {ema.min():.2f} |")
    if not rows:
        return []
    return [
        "",
        f"The sampler's failure EMA per segment at the last checkpoint. A prior over segments that all "
        f"fail (EMA >= {SATURATED_EMA}) is flat: it cannot prefer the hard ones.",
        "",
        *_table_head("arm", "seed", "segments", "saturated", "lowest EMA"),
        *rows,
    ]


def _paper_table_lines(spec: StudySpec, columns: tuple[str, ...]) -> list[str]:
    """The paper's own figures for the arms, in the columns it reports."""
    quoted = tuple(sorted({column for row in spec.paper.values() for column in row}, key=columns.index))
    lines = ["", spec.paper_caption, "", *_table_head("arm", *quoted)]
    for arm, row in spec.paper.items():
        lines.append(f"| {arm} | " + " | ".join(row.get(c, "–") for c in quoted) + " |")
    return lines


def copy_sampler_profiles(result: dict, out: Path) -> None:
    """Each arm's first seed's sampler profile beside the results (artifacts are not committed)."""
    for arm in result["arms"]:
        if arm["seeds"]:
            source = Path(arm["seeds"][0]["train_folder"]) / PROFILE_FILE
            shutil.copyfile(source, out.parent / f"{out.name}_profile_{arm['arm']}.png")


def smoothed(values: np.ndarray, window: int) -> np.ndarray:
    """Moving mean over `window` iterations along the last axis (the first window - 1 are dropped)."""
    kernel = np.ones(window) / window
    return np.apply_along_axis(lambda row: np.convolve(row, kernel, mode="valid"), -1, values)


def plot_curves(result: dict, path: Path, window: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import stats

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.4))
    for arm in result["arms"]:
        curves = [s["curve"] for s in arm["seeds"]]
        if not curves:
            continue
        length = min(len(c["iteration"]) for c in curves)
        span = min(window, length)  # a run shorter than the window is drawn unsmoothed
        iterations = np.asarray(curves[0]["iteration"][span - 1 : length])
        for ax, key in zip(axes, ("episode_length_s", "reward"), strict=True):
            values = smoothed(np.asarray([c[key][:length] for c in curves]), span)
            mean = values.mean(axis=0)
            ax.plot(iterations, mean, lw=1, label=f"{arm['arm']} (n={len(curves)})")
            if len(curves) > 1:
                half = stats.t.ppf(0.975, len(curves) - 1) * values.std(axis=0, ddof=1) / np.sqrt(len(curves))
                ax.fill_between(iterations, mean - half, mean + half, alpha=0.2)
    axes[0].set_ylabel("mean training episode length (s)")
    axes[1].set_ylabel("mean reward per step")
    for ax in axes:
        ax.set_xlabel("iteration")
    axes[0].legend(fontsize=7)
    fig.suptitle(
        f"{result['robot']} {result['clip']}: mean and 95 % CI over seeds ({window}-iteration moving mean)", fontsize=9
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write(result: dict, out: Path, window: int) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(result, indent=1) + "\n")
    out.with_suffix(".md").write_text(markdown(result))
    plot_curves(result, out.parent / f"{out.name}_curves.png", window)
    if result["study"] == "sampler":
        copy_sampler_profiles(result, out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("study", choices=sorted(SPECS))
    parser.add_argument("--arms", nargs="+", help="default: the study's arms")
    parser.add_argument("--seeds", nargs="+", type=int, help="default: 0 1 2 (residual), 0 1 (sampler)")
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--clip", default="0:10")
    parser.add_argument("--profile", default="cpu")
    parser.add_argument("--set", nargs="*", default=[], help="overrides for every trial")
    parser.add_argument("--out", type=Path, help="default: studies/results/<study>_study")
    parser.add_argument("--collect", action="store_true", help="only rewrite the results from finished trials")
    parser.add_argument("--smooth", type=int, default=25, help="moving-mean window of the curves, in iterations")
    parser.add_argument("--curve-window", type=int, default=200, help="iterations of the early and late curve means")
    args = parser.parse_args()
    spec = SPECS[args.study]
    args.arms = args.arms or list(spec.arms)
    args.seeds = args.seeds or list(spec.seeds)
    args.out = args.out or Path(f"studies/results/{args.study}_study")
    if not args.collect:
        for trial in trials(args):
            if seed_result(trial, args) is None and not run(trial, args):
                print(f"{trial.label}: failed (see the output above); going on", flush=True)
            write(summary(args), args.out, args.smooth)
    write(summary(args), args.out, args.smooth)
    print(f"wrote {args.out.with_suffix('.json')}")


if __name__ == "__main__":
    main()
