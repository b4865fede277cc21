"""Rerun recordings: the human skeleton and robot reference motions on one timeline.

Whole trajectories go in with `send_columns`, one call per entity, so a 4-minute clip is written
in well under a second.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr

from rd_pipeline.motion.human import HumanMotion
from rd_pipeline.motion.reference import ReferenceMotion

FRAME_TIMELINE = "frame"
TIME_TIMELINE = "time"
HUMAN_COLOR = (230, 140, 40)
ROBOT_COLOR = (60, 140, 230)


def _times(n_frames: int, fps: float) -> list[rr.TimeColumn]:
    frames = np.arange(n_frames)
    return [rr.TimeColumn(FRAME_TIMELINE, sequence=frames), rr.TimeColumn(TIME_TIMELINE, duration=frames / fps)]


def _log_skeleton(
    rec: rr.RecordingStream, entity: str, positions: np.ndarray, parents: np.ndarray, fps: float,
    color: tuple[int, int, int], radius: float,
) -> None:
    """Joints as points and bones as line segments, one row per frame."""
    n_frames, n_joints = positions.shape[:2]
    times = _times(n_frames, fps)
    rec.send_columns(
        f"{entity}/joints", indexes=times,
        columns=rr.Points3D.columns(positions=positions.reshape(-1, 3)).partition([n_joints] * n_frames),
    )
    children = np.flatnonzero(parents >= 0)
    bones = np.stack([positions[:, parents[children]], positions[:, children]], axis=2)  # (T, K, 2, 3)
    rec.send_columns(
        f"{entity}/bones", indexes=times,
        columns=rr.LineStrips3D.columns(strips=list(bones.reshape(-1, 2, 3))).partition([len(children)] * n_frames),
    )
    rec.log(f"{entity}/joints", rr.Points3D.from_fields(colors=[color], radii=[radius]), static=True)
    rec.log(f"{entity}/bones", rr.LineStrips3D.from_fields(colors=[color], radii=[radius * 0.5]), static=True)


def log_human(rec: rr.RecordingStream, human: HumanMotion, entity: str = "human") -> None:
    _log_skeleton(rec, entity, human.pos_w, human.parents, human.fps, HUMAN_COLOR, 0.02)


def log_reference(rec: rr.RecordingStream, reference: ReferenceMotion, body_parents: np.ndarray, entity: str) -> None:
    """A robot reference motion as its body frames linked to their parents."""
    _log_skeleton(rec, entity, reference.body_pos_w, body_parents, reference.fps, ROBOT_COLOR, 0.02)


def open_recording(name: str, out: Path | None) -> rr.RecordingStream:
    """A recording that streams to an `.rrd` file (headless), else to a spawned viewer."""
    rec = rr.RecordingStream(application_id="rd_pipeline", recording_id=name)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        rec.save(str(out))
    else:
        rec.spawn()
    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    return rec
