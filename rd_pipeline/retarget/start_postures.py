"""Postures the first frame may start from: the default pose, and the default pose with its knees
folded.

Frame by frame, the IK keeps the branch its first frame lands on. From the standing default, a
clip cut where the performer kneels lands on whichever branch the pose falls into first; a start
with the knees folded can sit back on the heels instead.
"""

from __future__ import annotations

import numpy as np

from rd_pipeline.errors import PipelineError
from rd_pipeline.retarget.lafan_joints import KNEES
from rd_pipeline.robots import Robot


def start_postures(robot: Robot, knee_bends: tuple[float, ...]) -> list[np.ndarray]:
    """Joint positions (config order) of the default pose with each knee moved by each fraction of
    the way from its default to its flexion end: 0 is the default pose itself."""
    default = robot.config.default_pos
    knees = _knee_joints(robot)
    postures = []
    for bend in knee_bends:
        joints = default.copy()
        for index, flexed in knees:
            joints[index] += bend * (flexed - default[index])
        postures.append(joints)
    return postures


def _knee_joints(robot: Robot) -> list[tuple[int, float]]:
    """(index in the config's joints, the range end the knee flexes towards) of the joint that moves
    each body mapped to a LAFAN1 knee. A knee bends further one way than the other: the end farther
    from zero is its flexion."""
    model = robot.model
    body_for = {human: body for body, human in robot.config.retarget_map.items()}
    names = list(robot.config.joint_names)
    knees = []
    for human_knee in KNEES:
        body = model.body(body_for[human_knee]).id
        joint = int(model.body_jntadr[body])
        name = model.joint(joint).name if joint >= 0 else None
        if name not in names:
            raise PipelineError(
                f"{robot.config.source}: the knee body '{body_for[human_knee]}' is not moved by one of joints.names"
            )
        low, high = model.jnt_range[joint]
        flexed = high if abs(high) >= abs(low) else low
        knees.append((names.index(name), float(flexed)))
    return knees
