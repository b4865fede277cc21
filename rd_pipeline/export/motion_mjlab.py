"""A reference motion as the npz that mjlab's and BeyondMimic's tracking tasks load.

Their `MotionLoader` reads `fps`, `joint_pos`, `joint_vel` (joints in the order of the robot model's
hinge joints) and `body_pos_w`, `body_quat_w` (wxyz), `body_lin_vel_w`, `body_ang_vel_w` for every
body of the model but the world, in the model's order; the task then picks its tracked bodies by
index into that list. `joint_names` and `body_names` say which column is which.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rd_pipeline.export.motion_csv import resample_root_and_joints
from rd_pipeline.motion.reference import ReferenceMotion, reference_from_joint_trajectory
from rd_pipeline.robots import Robot


def at_rate(reference: ReferenceMotion, robot: Robot, fps: float) -> ReferenceMotion:
    """`reference` at `fps`: the same motion, its body poses and velocities recomputed by FK."""
    if fps == reference.fps:
        return reference
    root_pos, root_quat_xyzw, joint_pos = resample_root_and_joints(reference, fps)
    root_quat = root_quat_xyzw[:, [3, 0, 1, 2]]
    no_contact = np.zeros((len(joint_pos), 2), dtype=bool)
    return reference_from_joint_trajectory(robot, fps, root_pos, root_quat, joint_pos, no_contact)


def write_mjlab_npz(reference: ReferenceMotion, robot: Robot, path: Path, fps: float) -> int:
    """Write `reference` at `fps` in mjlab's motion layout; returns the number of frames."""
    motion = at_rate(reference, robot, fps)
    model_order = np.argsort(robot.qpos_indices)
    arrays = {
        "fps": np.array([fps]),
        "joint_pos": motion.joint_pos[:, model_order].astype(np.float32),
        "joint_vel": motion.joint_vel[:, model_order].astype(np.float32),
        "body_pos_w": motion.body_pos_w.astype(np.float32),
        "body_quat_w": motion.body_quat_w.astype(np.float32),
        "body_lin_vel_w": motion.body_lin_vel_w.astype(np.float32),
        "body_ang_vel_w": motion.body_ang_vel_w.astype(np.float32),
        "joint_names": np.array([motion.joint_names[i] for i in model_order]),
        "body_names": np.array(motion.body_names),
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.name}.partial.npz")
    np.savez(partial, **arrays)
    partial.replace(path)
    return motion.n_frames
