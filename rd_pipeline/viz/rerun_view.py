"""Rerun recordings: the human skeleton and robot reference motions on one timeline.

Whole trajectories go in with `send_columns`, one call per entity, so a 4-minute clip is written
in well under a second.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import mujoco
import numpy as np
import rerun as rr

from rd_pipeline.files import write_bytes_whole
from rd_pipeline.motion.human import HumanMotion

FRAME_TIMELINE = "frame"
TIME_TIMELINE = "time"
HUMAN_COLOR = (230, 140, 40)
ROBOT_COLOR = (60, 140, 230)


def _times(n_frames: int, fps: float, first_frame: int = 0) -> list[rr.TimeColumn]:
    frames = np.arange(first_frame, first_frame + n_frames)
    return [rr.TimeColumn(FRAME_TIMELINE, sequence=frames), rr.TimeColumn(TIME_TIMELINE, duration=frames / fps)]


def _log_skeleton(
    rec: rr.RecordingStream,
    entity: str,
    positions: np.ndarray,
    parents: np.ndarray,
    fps: float,
    color: tuple[int, int, int],
    radius: float,
) -> None:
    """Joints as points and bones as line segments, one row per frame."""
    n_frames, n_joints = positions.shape[:2]
    times = _times(n_frames, fps)
    rec.send_columns(
        f"{entity}/joints",
        indexes=times,
        columns=rr.Points3D.columns(positions=positions.reshape(-1, 3)).partition([n_joints] * n_frames),
    )
    children = np.flatnonzero(parents >= 0)
    bones = np.stack([positions[:, parents[children]], positions[:, children]], axis=2)  # (T, K, 2, 3)
    rec.send_columns(
        f"{entity}/bones",
        indexes=times,
        columns=rr.LineStrips3D.columns(strips=list(bones.reshape(-1, 2, 3))).partition([len(children)] * n_frames),
    )
    rec.log(f"{entity}/joints", rr.Points3D.from_fields(colors=[color], radii=[radius]), static=True)
    rec.log(f"{entity}/bones", rr.LineStrips3D.from_fields(colors=[color], radii=[radius * 0.5]), static=True)


def log_human(rec: rr.RecordingStream, human: HumanMotion, entity: str = "human") -> None:
    _log_skeleton(rec, entity, human.pos_w, human.parents, human.fps, HUMAN_COLOR, 0.02)


def log_robot_meshes(
    rec: rr.RecordingStream,
    model: mujoco.MjModel,
    body_names: Sequence[str],
    body_pos_w: np.ndarray,
    body_quat_w: np.ndarray,
    fps: float,
    entity: str,
    color: tuple[int, int, int] = ROBOT_COLOR,
    first_frame: int = 0,
) -> None:
    """The robot's visual meshes, one static mesh per body, moved by per-frame body transforms
    (`body_pos_w` (T, B, 3), `body_quat_w` (T, B, 4) wxyz, bodies named by `body_names`).

    The meshes are decimated to their vertex sets as MuJoCo compiled them; each body's geoms are
    merged into one mesh in the body frame, so a frame costs one transform per body.
    """
    times = _times(len(body_pos_w), fps, first_frame)
    for b, name in enumerate(body_names):
        body_id = model.body(name).id
        vertices, faces = _body_mesh(model, body_id)
        if not len(vertices):
            continue
        path = f"{entity}/{name}"
        rec.log(
            path, rr.Mesh3D(vertex_positions=vertices, triangle_indices=faces, albedo_factor=[*color, 255]), static=True
        )
        quat_xyzw = body_quat_w[:, b][:, [1, 2, 3, 0]]
        rec.send_columns(
            path, indexes=times, columns=rr.Transform3D.columns(translation=body_pos_w[:, b], quaternion=quat_xyzw)
        )


def _body_mesh(model: mujoco.MjModel, body_id: int) -> tuple[np.ndarray, np.ndarray]:
    vertices = []
    faces = []
    count = 0
    for geom in range(model.ngeom):
        if model.geom_bodyid[geom] != body_id or model.geom_type[geom] != mujoco.mjtGeom.mjGEOM_MESH:
            continue
        mesh = model.geom_dataid[geom]
        v = model.mesh_vert[model.mesh_vertadr[mesh] : model.mesh_vertadr[mesh] + model.mesh_vertnum[mesh]]
        f = model.mesh_face[model.mesh_faceadr[mesh] : model.mesh_faceadr[mesh] + model.mesh_facenum[mesh]]
        rotation = np.empty(9)
        mujoco.mju_quat2Mat(rotation, model.geom_quat[geom])
        vertices.append(v @ rotation.reshape(3, 3).T + model.geom_pos[geom])
        faces.append(f + count)
        count += len(v)
    if not vertices:
        return np.empty((0, 3)), np.empty((0, 3), dtype=np.int64)
    return np.concatenate(vertices), np.concatenate(faces)


def log_points(
    rec: rr.RecordingStream, entity: str, positions: np.ndarray, fps: float, color: tuple[int, int, int], radius: float
) -> None:
    """Points over time, e.g. the retargeting's keypoint targets."""
    n_frames, n_points = positions.shape[:2]
    rec.send_columns(
        entity,
        indexes=_times(n_frames, fps),
        columns=rr.Points3D.columns(positions=positions.reshape(-1, 3)).partition([n_points] * n_frames),
    )
    rec.log(entity, rr.Points3D.from_fields(colors=[color], radii=[radius]), static=True)


def log_series(rec: rr.RecordingStream, entity: str, values: np.ndarray, fps: float) -> None:
    """A per-frame number as a plot on the motion's timeline (keypoint error, penetration, ...)."""
    rec.send_columns(entity, indexes=_times(len(values), fps), columns=rr.Scalars.columns(scalars=values))


def display_available() -> bool:
    """Whether a spawned viewer window could open here (a spawn without one waits forever)."""
    return sys.platform in ("darwin", "win32") or bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


@contextmanager
def open_recording(name: str, out: Path | None) -> Iterator[rr.RecordingStream]:
    """A recording to log into. With `out` it is kept in memory and written to that `.rrd` whole
    when the block ends (rerun's own file sink can hang on a full disk); without, it streams to a
    spawned viewer."""
    rec = rr.RecordingStream(application_id="rd_pipeline", recording_id=name)
    memory = rec.memory_recording() if out is not None else None
    if out is None:
        rec.spawn()
    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    yield rec
    if out is None or memory is None:
        rec.flush()
        return
    write_bytes_whole(out, memory.drain_as_bytes())
