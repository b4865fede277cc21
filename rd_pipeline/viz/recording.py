"""One recording per (robot, motion) from whatever motion artifacts exist."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.human import HUMAN_MOTION_FILE, HumanMotion
from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
from rd_pipeline.retarget.targets import TARGETS_FILE
from rd_pipeline.viz.rerun_view import log_human, log_points, log_robot_meshes, open_recording

TARGET_COLOR = (220, 60, 60)


def record_motion(robot: str, motion: str, artifact_dirs: dict[str, Path], out: Path | None) -> Path | None:
    """Log the human skeleton (parse) and the robot reference (retarget or import) found in `artifact_dirs`."""
    human_files = [d / HUMAN_MOTION_FILE for d in artifact_dirs.values() if (d / HUMAN_MOTION_FILE).is_file()]
    reference_files = [(name, d / REFERENCE_FILE) for name, d in artifact_dirs.items() if (d / REFERENCE_FILE).is_file()]
    if not human_files and not reference_files:
        raise PipelineError(f"nothing to show for {robot}/{motion}: no motion artifacts")
    rec = open_recording(f"{robot}_{motion}", out)
    for path in human_files:
        log_human(rec, HumanMotion.load(path))
    if reference_files:
        from rd_pipeline.robots import load_robot

        model = load_robot(robot).model
        for stage, path in reference_files:
            reference = ReferenceMotion.load(path)
            log_robot_meshes(rec, model, reference, entity=f"robot/{stage}")
            targets = path.parent / TARGETS_FILE
            if targets.is_file():
                with np.load(targets) as data:
                    log_points(rec, f"targets/{stage}", data["positions"], reference.fps, TARGET_COLOR, 0.015)
    rec.flush()
    return out
