"""Rerun recordings: the human skeleton and robot motions on one time axis, in seconds.

Every source goes on the `time` timeline at its own rate (the human at 30 fps, the robots at
50 fps), so a moment of the dance is the same moment for all of them. Whole trajectories go in
with `send_columns`, one call per entity, so a 4-minute clip is written in well under a second.
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

TIME_TIMELINE = "time"

# One colour per source, from the Okabe-Ito palette (told apart with the common colour blindnesses).
HUMAN_COLOR = (230, 159, 0)
REFERENCE_COLOR = (0, 114, 178)
TRACKED_COLOR = (0, 158, 115)
TARGET_COLOR = (204, 121, 167)
END_COLOR = (213, 94, 0)

LABEL_ABOVE_ROOT_M = 0.9
"""How far above its root a source's name floats (above the head of a person or robot)."""
LABEL_RADIUS_M = 0.03
END_RADIUS_M = 0.06
"""The marker where a rollout ended: larger than any joint, to be found at a glance."""


def _times(n_frames: int, fps: float, first_frame: int = 0) -> list[rr.TimeColumn]:
    frames = np.arange(first_frame, first_frame + n_frames)
    return [rr.TimeColumn(TIME_TIMELINE, duration=frames / fps)]


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
    log_label(rec, entity, "human (motion capture)", human.pos_w[:, 0], human.fps, HUMAN_COLOR)


def log_label(
    rec: rr.RecordingStream,
    entity: str,
    text: str,
    root_pos: np.ndarray,
    fps: float,
    color: tuple[int, int, int],
    first_frame: int = 0,
) -> None:
    """The source's name floating above its root (`root_pos` (T, 3)), so the view says who is who."""
    rec.send_columns(
        f"{entity}/label",
        indexes=_times(len(root_pos), fps, first_frame),
        columns=rr.Points3D.columns(positions=root_pos + [0.0, 0.0, LABEL_ABOVE_ROOT_M]),
    )
    rec.log(
        f"{entity}/label",
        rr.Points3D.from_fields(colors=[color], radii=[LABEL_RADIUS_M], labels=[text], show_labels=True),
        static=True,
    )


def log_end(rec: rr.RecordingStream, entity: str, seconds: float, where: np.ndarray, text: str) -> None:
    """Clear `entity` (and all below it) from `seconds` on, and leave a marker at `where` saying why:
    a robot that stopped must not stay standing in its last pose for the rest of the clip."""
    # Columns, not `log`: a logged row would also land on a wall-clock `log_time` timeline.
    at = [rr.TimeColumn(TIME_TIMELINE, duration=[seconds])]
    rec.send_columns(entity, indexes=at, columns=rr.Clear.columns(is_recursive=[True]))
    marker = rr.Points3D.columns(positions=[where], labels=[text])
    rec.send_columns(f"{entity}_end", indexes=at, columns=marker)
    style = rr.Points3D.from_fields(colors=[END_COLOR], radii=[END_RADIUS_M], show_labels=True)
    rec.log(f"{entity}_end", style, static=True)


def log_robot_meshes(
    rec: rr.RecordingStream,
    model: mujoco.MjModel,
    body_names: Sequence[str],
    body_pos_w: np.ndarray,
    body_quat_w: np.ndarray,
    fps: float,
    entity: str,
    color: tuple[int, int, int] = REFERENCE_COLOR,
    first_frame: int = 0,
) -> None:
    """The robot's visual meshes, one mesh per body, moved by per-frame body transforms
    (`body_pos_w` (T, B, 3), `body_quat_w` (T, B, 4) wxyz, bodies named by `body_names`).

    The meshes are decimated to their vertex sets as MuJoCo compiled them; each body's geoms are
    merged into one mesh in the body frame, so a frame costs one transform per body. Each mesh is
    logged once, at the first pose, not as static data: before that pose it would stand at the
    origin, and a `Clear` cannot take static data away.
    """
    times = _times(len(body_pos_w), fps, first_frame)
    start = _times(1, fps, first_frame)
    for b, name in enumerate(body_names):
        body_id = model.body(name).id
        vertices, faces = _body_mesh(model, body_id)
        if not len(vertices):
            continue
        path = f"{entity}/{name}"
        mesh = rr.Mesh3D.columns(vertex_positions=vertices, triangle_indices=faces, albedo_factor=[[*color, 255]])
        rec.send_columns(path, indexes=start, columns=_one_row(mesh))
        quat_xyzw = body_quat_w[:, b][:, [1, 2, 3, 0]]
        rec.send_columns(
            path, indexes=times, columns=rr.Transform3D.columns(translation=body_pos_w[:, b], quaternion=quat_xyzw)
        )


def _one_row(columns: rr.ComponentColumnList) -> list[rr.ComponentColumn]:
    """`columns` as a single row holding all their values (`send_columns` sends rows)."""
    return [column.partition([len(column.as_arrow_array())]) for column in columns]


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


def log_series(
    rec: rr.RecordingStream,
    entity: str,
    values: np.ndarray,
    fps: float,
    first_frame: int = 0,
    color: tuple[int, int, int] | None = None,
) -> None:
    """A per-frame number as a plot on the time axis (keypoint error, tracking error, ...), named
    by the last part of its entity path."""
    indexes = _times(len(values), fps, first_frame)
    rec.send_columns(entity, indexes=indexes, columns=rr.Scalars.columns(scalars=values))
    name = entity.rsplit("/", 1)[-1]
    colors = None if color is None else [color]
    rec.log(entity, rr.SeriesLines(names=[name], colors=colors), static=True)


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
