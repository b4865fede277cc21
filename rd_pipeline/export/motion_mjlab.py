"""A reference motion as the npz that mjlab's and BeyondMimic's tracking tasks load.

Their `MotionLoader` reads `fps`, `joint_pos`, `joint_vel` (joints in the order of the task robot's
hinge joints) and `body_pos_w`, `body_quat_w` (wxyz), `body_lin_vel_w`, `body_ang_vel_w` for every
body of that robot but the world, in its model order; the task then picks its tracked bodies by
index into that list. `joint_names` and `body_names` say which column is which.

The task robot is not always the pipeline's: mjlab's G1 is the 29-DoF model, the pipeline's the
23-DoF one (the paper's). `robots/interop/mjlab.toml` names the task model per robot; the motion is
laid out on it by joint name, with the joints the pipeline's model lacks at 0.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from rd_pipeline.export.motion_csv import joints_by_name, resample_root_and_joints
from rd_pipeline.files import written_whole
from rd_pipeline.motion.reference import ReferenceMotion, angular_velocity, body_poses, finite_difference
from rd_pipeline.paths import ROBOT_CONFIG_DIR
from rd_pipeline.robots import Robot
from rd_pipeline.robots.assets import asset_path

LAYOUTS_FILE = ROBOT_CONFIG_DIR / "interop" / "mjlab.toml"


def task_model(robot: Robot) -> tuple[mujoco.MjModel, dict[str, np.ndarray]]:
    """The model mjlab's tracking task for `robot` is built on (`LAYOUTS_FILE`), else the robot's own,
    and where that task puts body frames that the model has elsewhere on the same link."""
    layouts = tomllib.loads(LAYOUTS_FILE.read_text())
    entry = layouts.get(robot.config.name)
    if entry is None:
        return robot.model, {}
    model = mujoco.MjModel.from_xml_path(str(asset_path(entry["mjcf"])))
    offsets = {body: np.asarray(offset, dtype=float) for body, offset in entry.get("frame_offsets", {}).items()}
    return model, offsets


def hinge_names(model: mujoco.MjModel) -> list[str]:
    hinges = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE)
    return [model.joint(i).name for i in hinges]


def _root_and_joints(reference: ReferenceMotion, fps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(root_pos, root_quat wxyz, joint_pos) at `fps`; the reference's own frames at its rate."""
    if fps == reference.fps:
        return reference.root_pos, reference.root_quat, reference.joint_pos
    root_pos, root_quat_xyzw, joint_pos = resample_root_and_joints(reference, fps)
    return root_pos, root_quat_xyzw[:, [3, 0, 1, 2]], joint_pos


def write_mjlab_npz(reference: ReferenceMotion, robot: Robot, path: Path, fps: float) -> tuple[int, list[str]]:
    """Write `reference` at `fps` in the layout of mjlab's task model; returns the number of frames
    and the task model's joints the reference lacks (written as 0)."""
    model, frame_offsets = task_model(robot)
    root_pos, root_quat, joint_pos = _root_and_joints(reference, fps)
    hinges = hinge_names(model)
    layout = joints_by_name(joint_pos, reference.joint_names, hinges)
    qpos_address = model.jnt_qposadr[[model.joint(name).id for name in hinges]]
    bodies = np.arange(1, model.nbody)
    body_pos, body_quat = body_poses(model, root_pos, root_quat, qpos_address, layout, bodies)
    for body, offset in frame_offsets.items():
        index = model.body(body).id - 1
        turn = Rotation.from_quat(body_quat[:, index], scalar_first=True)
        body_pos[:, index] += turn.apply(offset)
    dt = 1.0 / fps
    arrays = {
        "fps": np.array([fps]),
        "joint_pos": layout.astype(np.float32),
        "joint_vel": finite_difference(layout, dt).astype(np.float32),
        "body_pos_w": body_pos.astype(np.float32),
        "body_quat_w": body_quat.astype(np.float32),
        "body_lin_vel_w": finite_difference(body_pos, dt).astype(np.float32),
        "body_ang_vel_w": angular_velocity(body_quat, dt).astype(np.float32),
        "joint_names": np.array(hinges),
        "body_names": np.array([model.body(i).name for i in range(1, model.nbody)]),
    }
    with written_whole(path, suffix=".npz") as partial:
        np.savez(partial, **arrays)  # type: ignore[arg-type]  # numpy's stub reads ** as allow_pickle
    missing = [name for name in hinges if name not in reference.joint_names]
    return len(layout), missing
