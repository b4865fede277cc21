"""Benchmark: the paper's residual study (learning-curve figure and Table r5) at CPU scale.

    python bench/residual_study.py [--arms absolute selective all reference_locked] [--seeds 0 1 2] \
        [--motion dance1_subject2] [--clip 0:10] [--profile cpu] [--set stage.param=value ...] \
        [--out bench/results/residual_study]

Runs `rd-pipeline ablate residual` one trial at a time, seed by seed (every arm has its first seed
before any arm has its second), always with `--resume`: a finished trial is cached in the artifact
store and an interrupted training continues from its last checkpoint, so rerunning the same
command continues the study. After every trial it rewrites `<out>.json`, `<out>.md` and
`<out>_curves.png` from the artifacts of the trials finished so far. Validation figures come from
each trial's `validate` report (the exported policy on the full mesh model); a seed's wall time is
its train stage's.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from rd_pipeline.commands import trial_artifact
from rd_pipeline.evaluation.metrics import ERROR_METRICS, t_interval
from rd_pipeline.rl.trainer import LOG_FILE
from rd_pipeline.sweeps.ablation import STUDIES
from rd_pipeline.sweeps.runner import Trial

ROBOT = "g1"
VALIDATION = ("start_zero_s", "completion_pct", "mean_survival_s", *ERROR_METRICS)
"""Table columns: start-zero survival, then the nominal policy's fixed-grid figures."""
PAPER_TABLE_R5 = {
    "absolute": {
        "completion_pct": "23.6 ± 3.9",
        "mean_survival_s": "37.2 ± 15.5",
        "E_mpbpe": "445.4 ± 55.3",
        "E_mpjpe": "174.0 ± 12.4",
    },
    "selective": {
        "completion_pct": "38.6 ± 22.6",
        "mean_survival_s": "45.0 ± 15.7",
        "E_mpbpe": "424.2 ± 37.4",
        "E_mpjpe": "163.9 ± 3.4",
    },
    "all": {
        "completion_pct": "24.3 ± 74.8",
        "mean_survival_s": "37.0 ± 49.5",
        "E_mpbpe": "682.0 ± 190.7",
        "E_mpjpe": "124.6 ± 42.4",
    },
}
"""The paper's Table r5 (dance2_subject4, 3 seeds, 226 fixed starts, GPU scale), quoted for comparison."""


def shared_sets(args: argparse.Namespace) -> tuple[str, ...]:
    """The overrides of every trial, in the order `ablate` puts them before the arm's."""
    return (f"train.clip={args.clip}", *args.set)


def trials(args: argparse.Namespace) -> list[Trial]:
    return [
        Trial(ROBOT, args.motion, seed, arm, shared_sets(args) + STUDIES["residual"][arm])
        for seed in args.seeds
        for arm in args.arms
    ]


def run(trial: Trial, args: argparse.Namespace) -> bool:
    command = [
        sys.executable,
        "-m",
        "rd_pipeline",
        "ablate",
        "residual",
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


def seed_result(trial: Trial, profile: str) -> dict | None:
    """One seed's row, or None while its trial has not finished."""
    train = trial_artifact(trial, profile, "train")
    validate = trial_artifact(trial, profile, "validate")
    if train is None or validate is None:
        return None
    report = json.loads((validate / "report.json").read_text())["nominal"]["policy"]
    manifest = json.loads((train / "manifest.json").read_text())
    params = manifest["params"]
    row = {
        "seed": trial.seed,
        "start_zero_s": report["start_zero"]["mean_survival_s"],
        **{m: report["fixed_grid"][m] for m in VALIDATION[1:]},
        "wall_min": round(manifest["duration_s"] / 60, 2),
        "samples": params["iterations"] * params["env"]["num_envs"] * params["ppo"]["steps_per_env"],
        "train_key": manifest["key"],
    }
    log = [json.loads(line) for line in (train / LOG_FILE).read_text().splitlines()]
    row["curve"] = {
        "iteration": [r["iteration"] for r in log],
        "episode_length_s": [r["episode_length_s"] or 0.0 for r in log],
        "reward": [r["reward"] for r in log],
    }
    return row


def summary(args: argparse.Namespace) -> dict:
    arms = []
    samples = set()
    for arm in args.arms:
        seeds = []
        for trial in trials(args):
            if trial.variant == arm:
                row = seed_result(trial, args.profile)
                if row is not None:
                    seeds.append(row)
                    samples.add(row["samples"])
        table = {m: t_interval([s[m] for s in seeds]) for m in (*VALIDATION, "wall_min")}
        arms.append({"arm": arm, "seeds": seeds, "table": table})
    return {
        "robot": ROBOT,
        "clip": f"{args.motion} {args.clip} s",
        "profile": args.profile,
        "sets": list(args.set),
        "samples_per_trial": min(samples) if len(samples) == 1 else sorted(samples),
        "arms": arms,
    }


def _cell(cell: dict) -> str:
    if cell["mean"] is None:
        return "–"
    return f"{cell['mean']:.2f}" + (f" ± {cell['ci95']:.2f}" if cell["ci95"] is not None else "")


def markdown(result: dict) -> str:
    header = ["arm", "n", *VALIDATION, "train min"]
    lines = [
        "# Residual study at CPU scale (the paper's Table r5 and learning-curve figure)",
        "",
        (
            f"{result['robot']}, {result['clip']}, `{result['profile']}` profile, "
            f"{result['samples_per_trial']} samples per trial. Written by `bench/residual_study.py`."
        ),
        "",
        (
            "Mean ± 95 % Student-t half-width over seeds. start_zero_s: one deterministic rollout from frame 0; "
            "the other columns: the fixed grid of starts (one per second), nominal physics, full mesh model."
        ),
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    for arm in result["arms"]:
        table = arm["table"]
        cells = [_cell(table[m]) for m in (*VALIDATION, "wall_min")]
        lines.append(f"| {arm['arm']} | {len(arm['seeds'])} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Per seed:",
        "",
        "| arm | seed | " + " | ".join(VALIDATION) + " | train min |",
        "|" + "---|" * (len(VALIDATION) + 3),
    ]
    for arm in result["arms"]:
        for s in arm["seeds"]:
            values = " | ".join(f"{s[m]}" for m in (*VALIDATION, "wall_min"))
            lines.append(f"| {arm['arm']} | {s['seed']} | {values} |")
    lines += [
        "",
        (
            "The paper's Table r5 (dance2_subject4, GPU scale; survival in s, errors in mm/mrad), for "
            "orientation only: a different motion and budget."
        ),
        "",
        "| arm | completion % | survival s | MPBPE | MPJPE |",
        "|---|---|---|---|---|",
    ]
    for arm, row in PAPER_TABLE_R5.items():
        lines.append(
            f"| {arm} | {row['completion_pct']} | {row['mean_survival_s']} | {row['E_mpbpe']} | {row['E_mpjpe']} |"
        )
    return "\n".join(lines) + "\n"


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
        iterations = np.asarray(curves[0]["iteration"][window - 1 : length])
        for ax, key in zip(axes, ("episode_length_s", "reward"), strict=True):
            values = smoothed(np.asarray([c[key][:length] for c in curves]), window)
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", nargs="+", default=["absolute", "selective", "all", "reference_locked"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--clip", default="0:10")
    parser.add_argument("--profile", default="cpu")
    parser.add_argument("--set", nargs="*", default=[], help="overrides for every trial")
    parser.add_argument("--out", type=Path, default=Path("bench/results/residual_study"))
    parser.add_argument("--collect", action="store_true", help="only rewrite the results from finished trials")
    parser.add_argument("--smooth", type=int, default=25, help="moving-mean window of the curves, in iterations")
    args = parser.parse_args()
    if not args.collect:
        for trial in trials(args):
            if seed_result(trial, args.profile) is None and not run(trial, args):
                print(f"{trial.label}: failed (see the output above); going on", flush=True)
            write(summary(args), args.out, args.smooth)
    write(summary(args), args.out, args.smooth)
    print(f"wrote {args.out.with_suffix('.json')}")


if __name__ == "__main__":
    main()
