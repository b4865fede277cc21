"""`validate`: exported policy + reference -> MuJoCo sim2sim report (policy beside the zero-action baseline)."""

from __future__ import annotations

from typing import Any

from rd_pipeline.artifacts.stage import Stage, StageContext
from rd_pipeline.evaluation.report import RECORDING_FILE
from rd_pipeline.evaluation.validation_config import ValidationConfig
from rd_pipeline.robots.assets import model_files


def _run(ctx: StageContext) -> dict[str, Any]:
    from rd_pipeline.evaluation.report import CONTROLLERS, plot_report, write_json, write_markdown
    from rd_pipeline.evaluation.validation import (
        load_exported_spec,
        recorded_rollout,
        reference_clip,
        rollout_pictures,
        validate_policy,
    )
    from rd_pipeline.robots import load_robot
    from rd_pipeline.viz.recording import record_tracking
    from rd_pipeline.viz.tracked import TRACKED_FILE

    config: ValidationConfig = ctx.params
    exported = ctx.upstream["deployable_policy"]
    made = ctx.upstream["reference"]
    spec = load_exported_spec(exported.path, made.key)
    clip = reference_clip(spec, made.stage, made.key, made.path)
    robot = load_robot(ctx.robot_name)
    protocols = 1 + len(config.randomized.seeds) + config.other_physics.enabled
    with ctx.progress(len(CONTROLLERS) * protocols, "sim2sim rollouts") as advance:
        validation = validate_policy(robot, ctx.motion, exported.path, exported.key, clip, config, advance)
    report = validation.report.details
    if config.render.enabled:
        report["pictures"] = rollout_pictures(validation, clip, config.render, ctx.out_dir)
    report["recording"] = RECORDING_FILE  # written below, after the report that links it
    write_json(report, ctx.out_dir)
    write_markdown(report, ctx.out_dir)
    plot_report(report, ctx.out_dir)
    recorded_rollout(validation, clip).save(ctx.out_dir / TRACKED_FILE)
    recording = f"{ctx.robot}_{ctx.motion}_sim2sim"
    record_tracking(robot.model, clip.motion, ctx.out_dir / TRACKED_FILE, recording, ctx.out_dir / RECORDING_FILE)
    return validation.report.headline()


STAGE = Stage(
    name="validate",
    version=9,
    description="exported policy + reference -> sim2sim report (nominal, randomized, other physics; "
    "tracking; filmstrip, video, plots, .rrd) beside zero-action",
    params=ValidationConfig,
    provides="validation_report",
    run=_run,
    inputs=lambda robot, motion: model_files(robot),
    requires=("deployable_policy", "reference"),
    headline=("start_zero_survival_s", "zero_action_start_zero_survival_s", "completion_pct", "tracked_pct"),
    report="report.md",
)
