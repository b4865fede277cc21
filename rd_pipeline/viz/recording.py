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
from rd_pipeline.viz.layout import Follow, Plot, send_layout
from rd_pipeline.viz.rerun_view import (
    REFERENCE_COLOR,
    TARGET_COLOR,
    TRACKED_COLOR,
    log_end,
    log_human,
    log_label,
    log_points,
    log_robot_meshes,
    log_series,
    open_recording,
)
from rd_pipeline.viz.tracked import TrackedRollout

SIDE_BY_SIDE_M = 1.0

RULER_UNITS = {"_m_s": "speeds (m/s)", "_deg": "angles (deg)", "_m": "distances (m)"}
"""The retargeting rulers by the unit their name ends with (body indices have none), one plot each."""


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
        plots = []
        follow = None
        for stage, path in reference_files:
            reference = ReferenceMotion.load(path)
            plots += _log_reference(rec, model, stage, reference, path.parent, tracked)
            follow = follow or _root(reference, f"robot/{stage}")
        send_layout(rec, plots, follow)
    return out


def _root(reference: ReferenceMotion, entity: str) -> Follow:
    """The reference robot's root body, for the camera to follow."""
    return Follow(f"{entity}/{reference.body_names[0]}", reference.body_pos_w[0, 0])


def _log_reference(
    rec, model, stage: str, reference: ReferenceMotion, folder: Path, tracked: Path | None
) -> list[Plot]:
    """One stage's robot reference (its artifact in `folder`), its IK targets and quality rulers,
    and the tracked robot; the plots of what it logged."""
    _log_robot(rec, model, reference, f"robot/{stage}", f"reference ({stage})")
    targets = folder / TARGETS_FILE
    if targets.is_file():
        with open_npz(targets) as data:
            log_points(rec, f"targets/{stage}", data["positions"], reference.fps, TARGET_COLOR, 0.015)
    plots = []
    series = folder / QUALITY_SERIES_FILE
    if series.is_file():
        plots += _log_rulers(rec, stage, series, reference.fps)
    if tracked is not None:
        plots += log_tracked(rec, model, reference, TrackedRollout.load(tracked), SIDE_BY_SIDE_M)
    return plots


def _log_rulers(rec, stage: str, series: Path, fps: float) -> list[Plot]:
    """The rulers as plots on the same time axis, one per unit: a bad frame is a spike to click on."""
    by_unit: dict[str, list[str]] = {}
    with open_npz(series) as data:
        for name in data.files:
            unit = next((u for suffix, u in RULER_UNITS.items() if name.endswith(suffix)), None)
            if unit is None:
                continue
            entity = f"quality/{stage}/{name}"
            log_series(rec, entity, data[name], fps)
            by_unit.setdefault(unit, []).append(entity)
    return [Plot(f"{stage}: {unit}", tuple(entities)) for unit, entities in by_unit.items()]


def _log_robot(rec, model, reference: ReferenceMotion, entity: str, label: str, first_frame: int = 0) -> None:
    """The robot of a reference motion as meshes on the time axis, named above its root."""
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
    log_label(rec, entity, label, reference.body_pos_w[:, 0], reference.fps, REFERENCE_COLOR, first_frame)


def log_tracked(rec, model, reference: ReferenceMotion, tracked: TrackedRollout, offset_m: float = 0.0) -> list[Plot]:
    """The simulated robot on the time axis, shifted `offset_m` along +y, its tracking errors as
    plots, and, where it failed before the clip's end, its removal with the cause at that moment."""
    names = [n for n in reference.body_names if model.body(n).id > 0]
    ids = [model.body(n).id for n in names]
    body_pos = tracked.body_pos[:, ids] + np.array([0.0, offset_m, 0.0])
    first = tracked.first_frame
    entity = "robot/tracked"
    log_robot_meshes(rec, model, names, body_pos, tracked.body_quat[:, ids], tracked.fps, entity, TRACKED_COLOR, first)
    log_label(rec, entity, "tracked (sim2sim)", body_pos[:, 0], tracked.fps, TRACKED_COLOR, first)
    # Error k is measured after step k, at pose k + 1.
    plots = [
        _log_error(rec, "tracking/body_error_m", tracked.body_error_m, tracked, "tracking error: bodies (m)"),
        _log_error(rec, "tracking/joint_error_rad", tracked.joint_error_rad, tracked, "tracking error: joints (rad)"),
    ]
    if tracked.ended_by:
        # Gone one frame after its last pose, so that failing pose is still seen.
        last = first + tracked.steps
        seconds = (last + 1) / tracked.fps
        cause = f"rollout ended at {last / tracked.fps:.2f} s: {tracked.ended_by}"
        log_end(rec, entity, seconds, body_pos[-1, 0], cause)
    return plots


def _log_error(rec, entity: str, values: np.ndarray, tracked: TrackedRollout, title: str) -> Plot:
    log_series(rec, entity, values, tracked.fps, tracked.first_frame + 1, TRACKED_COLOR)
    return Plot(title, (entity,))


def record_tracking(model, reference: ReferenceMotion, tracked: Path, name: str, out: Path) -> Path:
    """The reference robot and the tracked (simulated) robot side by side on one time axis (the
    tracked one shifted `SIDE_BY_SIDE_M` along +y); `reference` is the clip the rollout started on."""
    rollout = TrackedRollout.load(tracked)
    with open_recording(name, out) as rec:
        _log_robot(rec, model, reference, "robot/reference", "reference", rollout.first_frame)
        plots = log_tracked(rec, model, reference, rollout, SIDE_BY_SIDE_M)
        send_layout(rec, plots, _root(reference, "robot/reference"))
    return out
