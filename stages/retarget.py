"""`retarget`: human motion (parse) -> robot reference motion at 50 Hz by mink IK, with `quality.json`."""

from __future__ import annotations

import json
import time
from typing import Any

from rd_pipeline.artifacts.stage import Stage, StageContext
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.robots.assets import model_files


def _run(ctx: StageContext) -> dict[str, Any]:
    import numpy as np

    from rd_pipeline.motion.human import HUMAN_MOTION_FILE, HumanMotion
    from rd_pipeline.motion.reference import REFERENCE_FILE
    from rd_pipeline.retarget.quality import (
        QUALITY_FILE,
        QUALITY_SERIES_FILE,
        quality_series,
        summarize_quality,
    )
    from rd_pipeline.retarget.retarget import retarget
    from rd_pipeline.retarget.targets import TARGETS_FILE
    from rd_pipeline.robots import load_robot

    p: RetargetConfig = ctx.params
    robot = load_robot(ctx.robot_name)
    human = HumanMotion.load(ctx.upstream["human_motion"].path / HUMAN_MOTION_FILE)
    began = time.perf_counter()
    result = retarget(
        human,
        robot,
        p,
        track=lambda frames, total, label: ctx.track(frames, total, f"{ctx.robot} {label}"),
    )
    seconds = time.perf_counter() - began
    reference = result.reference
    targets = result.targets
    reference.save(ctx.out_dir / REFERENCE_FILE)
    targets.save(ctx.out_dir / TARGETS_FILE)
    feet = targets.foot_orientations(robot.config.foot_bodies)
    series = quality_series(robot, reference, targets.positions, targets.bodies, targets.human_pelvis, feet)
    np.savez(ctx.out_dir / QUALITY_SERIES_FILE, **series)  # type: ignore[arg-type]  # numpy's stub reads ** as allow_pickle
    quality = summarize_quality(robot, reference, series, frames_per_s=reference.n_frames / seconds)
    (ctx.out_dir / QUALITY_FILE).write_text(json.dumps(quality, indent=2) + "\n")
    return {
        **quality,
        "fps": reference.fps,
        "duration_s": round(reference.duration_s, 4),
        "human_scale": round(targets.human_scale, 4),
        "ground_lift_max_mm": round(1000 * result.ground_lift_max_m, 2),
        "repaired_windows": result.repaired_windows,
        "contact_fraction": [round(float(x), 4) for x in reference.foot_contact.mean(axis=0)],
        "body_contact_fraction": round(float(targets.body_contact.any(axis=1).mean()), 4),
    }


STAGE = Stage(
    name="retarget",
    version=33,
    description="human motion -> robot reference motion at 50 Hz (mink IK) + quality.json",
    params=RetargetConfig,
    provides="reference",
    run=_run,
    inputs=lambda robot, motion: model_files(robot),
    requires=("human_motion",),
    headline=("diverged_frames", "penetration_max_mm", "keypoint_error_p95_mm", "fps_frames_per_s"),
)
