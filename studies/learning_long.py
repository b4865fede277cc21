"""Benchmark: one long clip learned on this machine (selective residuals, combined sampler, `cpu` profile).

    python -m studies.learning_long --clip 0:30 [--iterations 2800] [--motion dance1_subject2] \
        [--set stage.param=value ...] [--out studies/results/learning_30s]

Runs the pipeline (as `rd-pipeline run --resume` would) (an interrupted training continues from its last checkpoint;
a finished one is cached), then writes `<out>.json`: `clip_s`, `start_zero_s`, `completion_pct`,
`wall_min` (with the minutes of each run a grown training continued), `samples`, the validation
figures of the exported checkpoint, which checkpoint that is and its start-zero survival on the
training model beside the final one's and every checkpoint's, the survival from each fixed-grid start
beside zero action's and the most it could be (to the clip's end), and how fast the reference
moves in each second. It copies the learning curve, the sampler profile, the survival per start
and the validation report beside it.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path
from typing import Any

from bench.common import head_commit
from rd_pipeline.api import workspace
from rd_pipeline.api.workspace import training_seconds, training_seconds_per_run
from rd_pipeline.artifacts.store import MANIFEST
from rd_pipeline.errors import PipelineError
from rd_pipeline.evaluation.report import REPORT_MD, SURVIVAL_PLOT
from rd_pipeline.evaluation.validation_report import ValidationReport
from rd_pipeline.motion.activity import joint_speed_p95_per_second
from rd_pipeline.stages.train import CURVE_FILE, PROFILE_FILE
from rd_pipeline.training.log import read_training_log
from studies.validation_fields import fixed_grid_fields, validated_reference

ROBOT = "g1"


def main() -> None:
    args = _parser().parse_args()
    sets = (f"train.clip={args.clip}", f"train.iterations={args.iterations}", *args.set)
    try:
        plan = workspace.plan(ROBOT, args.motion, args.profile, overrides=sets, seed=args.seed)
        workspace.run(plan, resume=True)
        result = _result(plan, args)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.with_suffix(".json").write_text(json.dumps(result, indent=2) + "\n")
        _copy_figures(plan, args.out)
    except (PipelineError, OSError) as exc:
        sys.exit(f"error: {exc}")
    print(json.dumps(result, indent=2))


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clip", default="0:30")
    parser.add_argument("--iterations", type=int, default=2800)
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--profile", default="cpu")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--set", nargs="*", default=[], help="further overrides")
    parser.add_argument("--out", type=Path, default=Path("studies/results/learning_30s"))
    parser.add_argument("--commit", default=None, help="the commit the code ran (default: git's HEAD here)")
    return parser


def _result(plan: workspace.Plan, args: argparse.Namespace) -> dict[str, Any]:
    train = workspace.required_artifact(plan, "train")
    export = workspace.required_artifact(plan, "export")
    validate = workspace.required_artifact(plan, "validate")
    manifest = json.loads((train / MANIFEST).read_text())
    trained = manifest["metrics"]
    validation = ValidationReport.load(validate)
    report = validation.details
    policy = report["nominal"]["policy"]
    params = manifest["params"]
    per_run = training_seconds_per_run(train)
    return {
        "robot": ROBOT,
        "motion": args.motion,
        "clip": args.clip,
        "clip_s": report["reference"]["duration_s"],
        "start_zero_s": validation.start_zero_survival_s,
        "completion_pct": validation.completion_pct,
        "mean_survival_s": validation.mean_survival_s,
        "mean_survival_ceiling_s": validation.mean_survival_ceiling_s,
        "E_g_mpbpe": validation.E_g_mpbpe,
        "E_mpbpe": policy["fixed_grid"]["E_mpbpe"],
        "zero_action_start_zero_s": validation.zero_action_start_zero_survival_s,
        "checkpoint": json.loads((export / MANIFEST).read_text())["metrics"]["checkpoint_iteration"],
        "training_model_start_zero_s": trained["best_start_zero_s"],
        "final_checkpoint_training_model_start_zero_s": trained["final_start_zero_s"],
        "wall_min": round(training_seconds(train) / 60, 2),
        "wall_min_per_run": {key: round(seconds / 60, 2) for key, seconds in per_run.items()},
        "samples": trained["samples"],
        "commit": args.commit or head_commit(),
        "physics_dt": params["env"]["physics_dt"],
        "decimation": params["env"]["decimation"],
        "solver_iterations": params["env"]["solver_iterations"],
        "ls_iterations": params["env"]["ls_iterations"],
        "ranks": params["ranks"],
        "action_mode": params["env"]["actions"]["mode"],
        "sampler": params["sampler"]["mode"],
        "train_key": manifest["key"],
        "training_model_start_zero_s_by_checkpoint": {
            row["iteration"]: row["start_zero_s"] for row in read_training_log(train) if "start_zero_s" in row
        },
        "export_key": report["policy_key"],
        **fixed_grid_fields(validation),
        "reference_joint_speed_p95_by_second": joint_speed_p95_per_second(validated_reference(plan, validation)),
    }


def _copy_figures(plan: workspace.Plan, out: Path) -> None:
    """The learning curve, the sampler profile, the survival per start and the validation report,
    beside the result file."""
    train = workspace.required_artifact(plan, "train")
    validate = workspace.required_artifact(plan, "validate")
    for source, suffix in (
        (train / CURVE_FILE, "_curve.png"),
        (train / PROFILE_FILE, "_sampler_profile.png"),
        (validate / REPORT_MD, "_validation.md"),
        (validate / SURVIVAL_PLOT, "_survival_per_start.png"),
    ):
        shutil.copyfile(source, out.parent / f"{out.name}{suffix}")


if __name__ == "__main__":
    main()
