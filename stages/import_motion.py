"""`import`: a LAFAN1_Retargeting_Dataset CSV -> the robot reference motion at 50 Hz, by forward kinematics."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rich.markup import escape

from rd_pipeline import paths
from rd_pipeline.artifacts.stage import Stage, StageContext
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion import Interpolation
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.params import require_positive
from rd_pipeline.robots.assets import model_files


@dataclass(frozen=True)
class ImportConfig:
    """Resampling of the dataset CSV and foot-contact labelling."""

    source_fps: float = 30.0
    """Frame rate of the dataset CSVs."""
    fps: float = 50.0
    """Frame rate of the reference motion (the policy rate)."""
    interpolation: Interpolation = "cubic"
    """Joint and root-position interpolation: `cubic` (smooth velocities) or `linear`."""
    contact: ContactThresholds = ContactThresholds()
    """When a robot foot counts as planted (its height above the clip's ground, and its speed)."""

    def __post_init__(self) -> None:
        require_positive(self, "source_fps", "fps")


def _inputs(robot: str | None, motion: str) -> dict[str, Path]:
    assert robot is not None
    csv = paths.csv_path(robot, motion)
    if csv is None:
        raise PipelineError(f"import of {robot}/{motion}: RD_RETARGETED_DIR is not set")
    return {"csv": csv, **model_files(robot)}


def _run(ctx: StageContext) -> dict[str, Any]:
    import numpy as np

    from rd_pipeline.motion.reference import REFERENCE_FILE
    from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
    from rd_pipeline.retarget.quality import (
        QUALITY_FILE,
        QUALITY_SERIES_FILE,
        quality_series,
        summarize_quality,
    )
    from rd_pipeline.robots import load_robot

    p = ctx.params
    robot = load_robot(ctx.robot_name)
    result = import_retargeted_csv(ctx.inputs["csv"], robot, p.source_fps, p.fps, p.interpolation, p.contact)
    for warning in result.warnings:
        ctx.console.print(f"[yellow]warning:[/] {escape(warning)}", highlight=False, soft_wrap=True)
    if result.dropped_joints:
        ctx.console.print(
            escape(f"  dataset joints not in the {ctx.robot} model, dropped: {', '.join(result.dropped_joints)}")
        )
    reference = result.reference
    reference.save(ctx.out_dir / REFERENCE_FILE)
    # The same ruler as the retarget stage, so the dataset and our retargeting share one table
    # (no human here: keypoint and pelvis-height rulers need the scaled human, `bench/retarget.py`).
    series = quality_series(robot, reference)
    np.savez(ctx.out_dir / QUALITY_SERIES_FILE, **series)  # type: ignore[arg-type]  # numpy's stub reads ** as allow_pickle
    quality = summarize_quality(robot, reference, series)
    (ctx.out_dir / QUALITY_FILE).write_text(json.dumps(quality, indent=2) + "\n")
    return {
        **quality,
        "fps": reference.fps,
        "duration_s": round(reference.duration_s, 4),
        "source_frames": result.source_frames,
        "dropped_joints": list(result.dropped_joints),
        "contact_fraction": [round(float(x), 4) for x in reference.foot_contact.mean(axis=0)],
    }


STAGE = Stage(
    name="import",
    version=4,
    description="LAFAN1_Retargeting_Dataset CSV -> robot reference motion at 50 Hz",
    params=ImportConfig,
    provides="reference",
    run=_run,
    inputs=_inputs,
    source="csv",
    headline=("duration_s", "penetration_max_mm"),
)
