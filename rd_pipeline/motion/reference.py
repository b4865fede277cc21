"""The robot reference motion (SPEC format; field names follow mjlab/BeyondMimic motion files)."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from rd_pipeline.errors import PipelineError
from rd_pipeline.files import open_npz
from rd_pipeline.robots import Robot

REFERENCE_FILE = "reference.npz"
"""File name of a reference motion inside an artifact."""


@dataclass(frozen=True)
class ReferenceMotion:
    """A robot trajectory at a fixed rate, with world-frame body poses and velocities."""

    fps: float
    """Frames per second (50 for every artifact the pipeline writes)."""
    joint_names: tuple[str, ...]
    """Actuated joints in the robot config's order."""
    body_names: tuple[str, ...]
    """Every body of the model but the world."""
    joint_pos: np.ndarray
    """(T, J) joint angles, rad."""
    joint_vel: np.ndarray
    """(T, J) joint velocities, rad/s."""
    root_pos: np.ndarray
    """(T, 3) floating-base position, m."""
    root_quat: np.ndarray
    """(T, 4) floating-base orientation, wxyz."""
    body_pos_w: np.ndarray
    """(T, B, 3) body positions in the world."""
    body_quat_w: np.ndarray
    """(T, B, 4) body orientations in the world, wxyz."""
    body_lin_vel_w: np.ndarray
    """(T, B, 3) body linear velocities in the world, m/s."""
    body_ang_vel_w: np.ndarray
    """(T, B, 3) body angular velocities in the world, rad/s."""
    foot_contact: np.ndarray
    """(T, 2) left/right foot in contact with the ground."""

    @property
    def n_frames(self) -> int:
        return self.joint_pos.shape[0]

    @property
    def duration_s(self) -> float:
        return self.n_frames / self.fps

    def seconds(self) -> list[slice]:
        """Frame slices of each second of this motion, the last, partial one included."""
        window = round(self.fps)
        return [slice(start, start + window) for start in range(0, self.n_frames, window)]

    def frames(self, start: int, end: int) -> ReferenceMotion:
        """Frames [start, end) of this motion (a training clip)."""
        per_frame = {
            f.name: getattr(self, f.name)[start:end]
            for f in fields(self)
            if f.name not in ("fps", "joint_names", "body_names")
        }
        return replace(self, **per_frame)

    def save(self, path: Path) -> None:
        arrays = {f.name: getattr(self, f.name) for f in fields(self)}
        arrays["joint_names"] = np.array(self.joint_names)
        arrays["body_names"] = np.array(self.body_names)
        np.savez(path, **arrays)

    @classmethod
    def load(cls, path: Path) -> ReferenceMotion:
        with open_npz(path) as data:
            missing = [f.name for f in fields(cls) if f.name not in data]
            if missing:
                raise PipelineError(f"{path}: reference motion lacks field '{missing[0]}'")
            values: dict[str, Any] = {f.name: data[f.name] for f in fields(cls)}
        values["fps"] = float(values["fps"])
        values["joint_names"] = tuple(str(n) for n in values["joint_names"])
        values["body_names"] = tuple(str(n) for n in values["body_names"])
        return cls(**values)


def reference_from_joint_trajectory(
    robot: Robot,
    fps: float,
    root_pos: np.ndarray,
    root_quat: np.ndarray,
    joint_pos: np.ndarray,
    foot_contact: np.ndarray,
) -> ReferenceMotion:
    """Complete a joint-space trajectory with body poses (MuJoCo FK) and finite-difference velocities."""
    body_ids = np.array(list(robot.body_ids.values()))
    body_pos, body_quat = body_poses(robot.model, root_pos, root_quat, robot.qpos_indices, joint_pos, body_ids)
    dt = 1.0 / fps
    return ReferenceMotion(
        fps=fps,
        joint_names=robot.config.joint_names,
        body_names=tuple(robot.body_names),
        joint_pos=joint_pos,
        joint_vel=finite_difference(joint_pos, dt),
        root_pos=root_pos,
        root_quat=root_quat,
        body_pos_w=body_pos,
        body_quat_w=body_quat,
        body_lin_vel_w=finite_difference(body_pos, dt),
        body_ang_vel_w=angular_velocity(body_quat, dt),
        foot_contact=foot_contact,
    )


def body_poses(
    model: mujoco.MjModel,
    root_pos: np.ndarray,
    root_quat: np.ndarray,
    qpos_address: np.ndarray,
    joint_pos: np.ndarray,
    body_ids: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(T, B, 3) world positions and (T, B, 4) wxyz orientations of `body_ids` by MuJoCo forward
    kinematics of a floating-base trajectory, `joint_pos` written at `qpos_address`."""
    data = mujoco.MjData(model)
    n_frames = joint_pos.shape[0]
    body_pos = np.empty((n_frames, len(body_ids), 3))
    body_quat = np.empty((n_frames, len(body_ids), 4))
    for t in range(n_frames):
        data.qpos[:3] = root_pos[t]
        data.qpos[3:7] = root_quat[t]
        data.qpos[qpos_address] = joint_pos[t]
        mujoco.mj_kinematics(model, data)
        body_pos[t] = data.xpos[body_ids]
        body_quat[t] = data.xquat[body_ids]
    return body_pos, body_quat


def finite_difference(values: np.ndarray, dt: float) -> np.ndarray:
    """Central differences inside, one-sided at the ends; consistent with the sampled positions."""
    if values.shape[0] < 2:
        return np.zeros_like(values)
    return np.gradient(values, dt, axis=0)


def angular_velocity(quat_wxyz: np.ndarray, dt: float) -> np.ndarray:
    """World-frame angular velocity (T, ..., 3) from orientations (T, ..., 4), central differences."""
    shape = quat_wxyz.shape[:-1]
    if shape[0] < 2:
        return np.zeros((*shape, 3))
    rot = Rotation.from_quat(quat_wxyz.reshape(-1, 4)[:, [1, 2, 3, 0]])
    rot = rot.as_matrix().reshape(*shape, 3, 3)
    # R_next R_prev^T is the world-frame rotation over the interval.
    prev = np.concatenate([rot[:1], rot[:-1]])
    nxt = np.concatenate([rot[1:], rot[-1:]])
    span = np.full(shape[0], 2.0 * dt)
    span[0] = span[-1] = dt
    delta = np.einsum("...ab,...cb->...ac", nxt, prev)
    rotvec = Rotation.from_matrix(delta.reshape(-1, 3, 3)).as_rotvec().reshape(*shape, 3)
    return rotvec / span.reshape(-1, *([1] * (len(shape))))
