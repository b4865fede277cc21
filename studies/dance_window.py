"""Benchmark: a window of dance learned and validated, grown over as many sittings as it takes.

    python -m studies.dance_window [--robot g1] [--motion dance1_subject2] [--clip 11:21 | --busiest 10 [--speed-quantile 1]]
        [--source bvh|csv] [--profile cpu] [--iterations 3300] [--set stage.param=value ...]
        [--out studies/results/dance_window.json] [--commit SHA]
    python -m studies.dance_window --profile paper --until train --fill-minutes 6   # a GPU lease

Runs the pipeline as `rd-pipeline run --resume` would: an interrupted training continues from its
last checkpoint, and a longer `--iterations` grows the finished shorter run. `--busiest N` trains
the N-second window of the take whose reference joint speed (p95) is the highest, or with
`--speed-quantile Q` the one nearest that quantile of the take's windows (0.5: a typical stretch).
`--fill-minutes M` first trains `--probe-iterations`, times them, and grows the run to the
iterations that fill M minutes (the iteration count, not the clock, keys the artifact).

Unless `--until train`, writes `<out>` with the exported checkpoint's figures on the 500 Hz mesh
model (`validate`), every scored checkpoint's training-model start-zero survival against samples,
the survival from each fixed-grid start beside zero action's and the most it could be (to the
window's end; their mean is `mean_survival_ceiling_s`), the options trained with, and
`<out stem>_curve.png` (start-zero against samples on a log axis; per-start survival) and
`<out stem>_sampler_profile.png` (the train stage's plot of the sampler's last failure rates).
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from bench.common import head_commit, training_hours
from rd_pipeline.api import windows, workspace
from rd_pipeline.artifacts.store import MANIFEST
from rd_pipeline.errors import PipelineError
from rd_pipeline.evaluation.validation_report import ValidationReport
from rd_pipeline.motion.activity import joint_speed_p95_per_second
from rd_pipeline.stages.train import PROFILE_FILE
from rd_pipeline.training.log import read_training_log
from studies.validation_fields import fixed_grid_fields, validated_reference

OPTIONS = {
    "backend": ("env", "backend"),
    "device": ("env", "device"),
    "num_envs": ("env", "num_envs"),
    "physics_dt": ("env", "physics_dt"),
    "decimation": ("env", "decimation"),
    "solver_iterations": ("env", "solver_iterations"),
    "ls_iterations": ("env", "ls_iterations"),
    "action_mode": ("env", "actions", "mode"),
    "sampler": ("sampler", "mode"),
    "failure_credit": ("sampler", "failure_credit"),
    "motion_far_height_only": ("env", "terminations", "motion_far_height_only"),
    "mixed_precision": ("ppo", "mixed_precision"),
    "ranks": ("ranks",),
    "seed": ("seed",),
}
"""Result-file name -> path in the train params: the options a reader needs to repeat the run."""


def main() -> None:
    args = _parser().parse_args()
    try:
        clip = args.clip or _window_clip(args)
        plan = _plan(args, clip, args.iterations)
        if args.fill_minutes:
            plan = _fill(args, clip)
        workspace.run(plan, resume=True, until=args.until)
        if args.until == "train":
            return
        result = _result(plan, clip, args.commit or head_commit())
    except (PipelineError, ValueError) as exc:
        sys.exit(f"error: {exc}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    _plot(result, args.out.with_name(f"{args.out.stem}_curve.png"))
    # The sampler's last failure rates and probabilities, as the train stage drew them.
    train = workspace.required_artifact(plan, "train")
    shutil.copyfile(train / PROFILE_FILE, args.out.with_name(f"{args.out.stem}_sampler_profile.png"))
    headline = {key: value for key, value in result.items() if not isinstance(value, (list, dict))}
    print(json.dumps(headline, indent=2))


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--clip", default=None, help="start:end seconds (default: --busiest)")
    parser.add_argument("--busiest", type=int, default=10, help="window length (s) when --clip is not given")
    parser.add_argument(
        "--speed-quantile",
        type=_quantile,
        default=1.0,
        help="which window when --clip is not given: nearest this quantile of the windows' joint speed (1: busiest)",
    )
    parser.add_argument(
        "--source",
        choices=("bvh", "csv"),
        default=None,
        help="the motion's source: bvh (parse + retarget) or csv (the dataset's retargeting); default: bvh where present",
    )
    parser.add_argument("--profile", default="cpu")
    parser.add_argument("--iterations", type=int, default=3300)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--set", nargs="*", default=[], help="further overrides")
    parser.add_argument("--until", default=None, help="last stage to run (train: no result file)")
    parser.add_argument("--fill-minutes", type=float, default=None)
    parser.add_argument("--probe-iterations", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path("studies/results/dance_window.json"))
    parser.add_argument("--commit", default=None, help="the commit the code ran (default: git's HEAD here)")
    return parser


def _quantile(text: str) -> float:
    """A quantile, refused before any stage runs when it is not a number in [0, 1]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"{text} is outside [0, 1]")
    return value


def _plan(args: argparse.Namespace, clip: str, iterations: int) -> workspace.Plan:
    sets = (f"train.clip={clip}", f"train.iterations={iterations}", *args.set)
    return workspace.plan(args.robot, args.motion, args.profile, overrides=sets, seed=args.seed, source=args.source)


def _window_clip(args: argparse.Namespace) -> str:
    """The `--busiest`-second window of the whole take's reference at `--speed-quantile` of its
    windows' joint speed (what `rd-pipeline run --window N --window-speed Q` chooses)."""
    whole = workspace.plan(args.robot, args.motion, args.profile, seed=args.seed, source=args.source)
    windows.check_window(whole, args.busiest, args.speed_quantile)
    workspace.run(whole, until=workspace.providing(whole, "reference"))
    window = windows.speed_window(whole, args.busiest, args.speed_quantile)
    print(
        f"{args.busiest} s window at speed quantile {args.speed_quantile:g}: {window.clip} s, "
        f"joint speed p95 {window.joint_speed_p95} rad/s"
    )
    return window.clip


def _fill(args: argparse.Namespace, clip: str) -> workspace.Plan:
    """Train the probe, time its steady iterations and return the plan that fills the minutes."""
    probe = _plan(args, clip, args.probe_iterations)
    workspace.run(probe, resume=True, until="train")
    train = workspace.required_artifact(probe, "train")
    rows = read_training_log(train)
    seconds_per_iteration = statistics.median(row["seconds"] for row in rows[1:])
    spent = json.loads((train / MANIFEST).read_text())["duration_s"]
    left = args.fill_minutes * 60 - spent
    iterations = args.probe_iterations + max(0, int(left / seconds_per_iteration))
    print(f"probe: {seconds_per_iteration:.2f} s per iteration after {spent:.0f} s; growing to {iterations}")
    return _plan(args, clip, iterations)


def _result(plan: workspace.Plan, clip: str, commit: str) -> dict[str, Any]:
    train = workspace.required_artifact(plan, "train")
    export = workspace.required_artifact(plan, "export")
    validate = workspace.required_artifact(plan, "validate")
    manifest = json.loads((train / MANIFEST).read_text())
    params = manifest["params"]
    samples = manifest["metrics"]["samples"]
    per_iteration = samples / params["iterations"]
    validation = ValidationReport.load(validate)
    details = validation.details
    return {
        "robot": plan.robot,
        "motion": plan.motion,
        "clip": clip,
        "source": plan.pipeline.source,
        "samples": samples,
        **training_hours(train),
        "samples_per_s_median": manifest["metrics"]["samples_per_s_median"],
        "commit": commit,
        "start_zero_s": validation.start_zero_survival_s,
        "mean_survival_s": validation.mean_survival_s,
        "mean_survival_ceiling_s": validation.mean_survival_ceiling_s,
        "zero_action_start_zero_s": validation.zero_action_start_zero_survival_s,
        "E_mpbpe": details["nominal"]["policy"]["fixed_grid"]["E_mpbpe"],
        "E_mpjpe": validation.E_mpjpe,
        "checkpoints": [
            {
                "iteration": row["iteration"],
                "samples": round(row["iteration"] * per_iteration),
                "training_model_start_zero_s": row["start_zero_s"],
                "training_model_completion": row["completion"],
            }
            for row in read_training_log(train)
            if "start_zero_s" in row
        ],
        "exported_checkpoint": json.loads((export / MANIFEST).read_text())["metrics"]["checkpoint_iteration"],
        "checkpoint_rule": validation.checkpoint_rule,
        "protocols": validation.protocols,
        "tracked_pct": validation.tracked_pct,
        "completion_pct": validation.completion_pct,
        "E_g_mpbpe": validation.E_g_mpbpe,
        "options": {name: _lookup(params, path) for name, path in OPTIONS.items()},
        "profile": plan.profile,
        "train_key": manifest["key"],
        "export_key": details["policy_key"],
        **fixed_grid_fields(validation),
        "reference_joint_speed_p95_by_second": joint_speed_p95_per_second(validated_reference(plan, validation)),
    }


def _lookup(params: dict[str, Any], path: tuple[str, ...]) -> Any:
    value: Any = params
    for name in path:
        value = value[name]
    return value


def _plot(result: dict[str, Any], path: Path) -> None:
    """Start-zero survival against samples (log axis) and survival per fixed-grid start."""
    figure, (curve, starts) = plt.subplots(1, 2, figsize=(12, 4.2))
    checkpoints = result["checkpoints"]
    curve.semilogx(
        [c["samples"] for c in checkpoints],
        [c["training_model_start_zero_s"] for c in checkpoints],
        "o-",
        ms=3,
        label="training model, each checkpoint",
    )
    exported = next(c for c in checkpoints if c["iteration"] == result["exported_checkpoint"])
    curve.plot([exported["samples"]], [result["start_zero_s"]], "r*", ms=12, label="exported, 500 Hz mesh model")
    curve.axhline(result["zero_action_start_zero_s"], color="gray", ls="--", label="zero action")
    curve.set(
        xlabel="PPO samples",
        ylabel="start-zero survival (s)",
        title=f"{result['robot']} {result['motion']} {result['clip']} s",
    )
    curve.legend(fontsize=8)
    starts.plot(result["fixed_grid_start_s"], result["fixed_grid_survival_s"], "o-", ms=3, label="policy")
    starts.plot(
        result["fixed_grid_start_s"],
        result["fixed_grid_zero_action_survival_s"],
        "s--",
        ms=3,
        color="gray",
        label="zero action",
    )
    starts.plot(
        result["fixed_grid_start_s"], result["fixed_grid_most_s"], ":", color="black", label="to the clip's end"
    )
    starts.set(
        xlabel="start in clip (s)", ylabel="survival (s)", title="survival per fixed-grid start, 500 Hz mesh model"
    )
    starts.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


if __name__ == "__main__":
    main()
