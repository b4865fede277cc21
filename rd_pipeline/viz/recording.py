"""One recording per (robot, motion) from whatever motion artifacts exist."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rd_pipeline.errors import PipelineError
from rd_pipeline.files import open_npz
from rd_pipeline.motion.human import HUMAN_MOTION_FILE, HumanMotion
from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
from rd_pipeline.retarget.quality import QUALITY_SERIES_FILE
from rd_pipeline.retarget.targets import TARGETS_FILE
from rd_pipeline.viz.rerun_view import log_human, log_points, log_robot_meshes, log_series, open_recording

TARGET_COLOR = (220, 60, 60)


def record_motion(
    robot: str, motion: str, artifact_dirs: dict[str, Path], out: Path | None, tracked: Path | None = None
) -> Path | None:
    """Log the human skeleton (parse), the robot reference (retarget or import) found in
    `artifact_dirs` and, given a validation's `tracked.npz`, the simulated robot beside them."""
    human_files = [d / HUMAN_MOTION_FILE for d in artifact_dirs.values() if (d / HUMAN_MOTION_FILE).is_file()]
    reference_files = [
        (name, d / REFERENCE_FILE) for name, d in artifact_dirs.items() if (d / REFERENCE_FILE).is_file()
    ]
    if not human_files and not reference_files:
        raise PipelineError(f"nothing to show for {robot}/{motion}: no motion artifacts")
    model = None
    if reference_files:
        from rd_pipeline.robots import load_robot

        model = load_robot(robot).model
    with open_recording(f"{robot}_{motion}", out) as rec:
        for path in human_files:
            log_human(rec, HumanMotion.load(path))
        for stage, path in reference_files:
            _log_reference(rec, model, stage, path, tracked)
    return out


def _log_reference(rec, model, stage: str, path: Path, tracked: Path | None) -> None:
    """One stage's robot reference, its IK targets and quality rulers, and the tracked robot."""
    reference = ReferenceMotion.load(path)
    _log_robot(rec, model, reference, f"robot/{stage}")
    targets = path.parent / TARGETS_FILE
    if targets.is_file():
        with open_npz(targets) as data:
            log_points(rec, f"targets/{stage}", data["positions"], reference.fps, TARGET_COLOR, 0.015)
    series = path.parent / QUALITY_SERIES_FILE
    if series.is_file():
        # The rulers as plots on the same timeline: a bad frame is a spike to click on.
        with open_npz(series) as data:
            for name in data.files:
                if name.endswith(("_m", "_m_s", "_deg")):  # measures, not body indices
                    log_series(rec, f"quality/{stage}/{name}", data[name], reference.fps)
    if tracked is not None:
        log_tracked(rec, model, reference, tracked, SIDE_BY_SIDE_M)


def _log_robot(rec, model, reference: ReferenceMotion, entity: str, first_frame: int = 0) -> None:
    """The robot of a reference motion as meshes on the frame timeline."""
    log_robot_meshes(
        rec,
        model,
        reference.body_names,
        reference.body_pos_w,
        reference.body_quat_w,
        reference.fps,
        entity,
        first_frame=first_frame,
    )


TRACKED_COLOR = (240, 150, 40)
SIDE_BY_SIDE_M = 1.0
TRACKED_FILE = "tracked.npz"
"""Body poses of the start-zero sim2sim rollout, written by `validate` for recordings."""


def save_tracked(path: Path, body_pos: np.ndarray, body_quat: np.ndarray, first_frame: int, fps: float) -> None:
    np.savez(path, body_pos=body_pos, body_quat=body_quat, first_frame=first_frame, fps=fps)


def log_tracked(rec, model, reference: ReferenceMotion, tracked: Path, offset_m: float = 0.0) -> None:
    """The simulated robot of a `tracked.npz` on the reference's frame timeline, shifted `offset_m` along +y."""
    with open_npz(tracked) as data:
        body_pos = data["body_pos"]
        body_quat = data["body_quat"]
        first = int(data["first_frame"])
    names = [n for n in reference.body_names if model.body(n).id > 0]
    ids = [model.body(n).id for n in names]
    log_robot_meshes(
        rec,
        model,
        names,
        body_pos[:, ids] + np.array([0.0, offset_m, 0.0]),
        body_quat[:, ids],
        reference.fps,
        "robot/tracked",
        color=TRACKED_COLOR,
        first_frame=first,
    )


def record_tracking(
    model, reference: ReferenceMotion, tracked: Path, name: str, out: Path, first_frame: int = 0
) -> Path:
    """The reference robot and the tracked (simulated) robot side by side on one timeline (the
    tracked one shifted `SIDE_BY_SIDE_M` along +y); `reference` is a clip starting at `first_frame`."""
    with open_recording(name, out) as rec:
        _log_robot(rec, model, reference, "robot/reference", first_frame)
        log_tracked(rec, model, reference, tracked, SIDE_BY_SIDE_M)
    return out
