"""A reference motion as a LAFAN1_Retargeting_Dataset CSV, the layout Unitree's tools read.

One row per frame, no header: root position xyz (m), root quaternion xyzw, then one angle (rad) per
column of the robot's dataset layout (`RobotConfig.csv_joints`). Columns for joints the configured
model does not have (the 29-DoF G1's waist roll and pitch on the 23-DoF model) are written as 0,
the pose those joints hold in the model.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, Slerp

from rd_pipeline.files import written_whole
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.robots.config import RobotConfig


def resample_root_and_joints(reference: ReferenceMotion, fps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(root_pos (T', 3), root_quat xyzw (T', 4), joint_pos (T', J)) at `fps`, over the same duration.

    Positions and angles follow a cubic spline through the frames, the root orientation a slerp; the
    last sample holds the last frame, as the importer does.
    """
    source_t = np.arange(reference.n_frames) / reference.fps
    n_target = round(reference.duration_s * fps)
    target_t = np.minimum(np.arange(n_target) / fps, source_t[-1])
    root_pos = CubicSpline(source_t, reference.root_pos, axis=0)(target_t)
    joint_pos = CubicSpline(source_t, reference.joint_pos, axis=0)(target_t)
    rotations = Rotation.from_quat(reference.root_quat, scalar_first=True)
    root_quat = Slerp(source_t, rotations)(target_t).as_quat()
    return root_pos, root_quat, joint_pos


def joints_by_name(joint_pos: np.ndarray, names: Sequence[str], layout: Sequence[str]) -> np.ndarray:
    """(T, len(layout)) angles of `joint_pos` (columns `names`) in another joint order; joints of
    `layout` missing from `names` are 0."""
    columns = np.zeros((len(joint_pos), len(layout)))
    for i, name in enumerate(layout):
        if name in names:
            columns[:, i] = joint_pos[:, names.index(name)]
    return columns


def write_dataset_csv(reference: ReferenceMotion, config: RobotConfig, path: Path, fps: float) -> int:
    """Write `reference` at `fps` in the dataset layout of `config`; returns the number of rows."""
    root_pos, root_quat, joint_pos = resample_root_and_joints(reference, fps)
    columns = joints_by_name(joint_pos, reference.joint_names, config.csv_joints)
    table = np.concatenate([root_pos, root_quat, columns], axis=1)
    with written_whole(path) as partial:
        np.savetxt(partial, table, delimiter=",", fmt="%.9g")
    return len(table)
