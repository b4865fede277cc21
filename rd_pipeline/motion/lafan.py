"""The LAFAN1 convention: Y-up, centimetres."""

import numpy as np

LAFAN_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""A +90 degree turn about X: maps LAFAN1's Y-up world to the pipeline's Z-up one, keeping handedness."""
LAFAN_CM_TO_M = 0.01
"""LAFAN1 lengths are in centimetres."""
LAFAN_JOINTS = (
    "Hips",
    "LeftUpLeg",
    "LeftLeg",
    "LeftFoot",
    "LeftToe",
    "RightUpLeg",
    "RightLeg",
    "RightFoot",
    "RightToe",
    "Spine",
    "Spine1",
    "Spine2",
    "Neck",
    "Head",
    "LeftShoulder",
    "LeftArm",
    "LeftForeArm",
    "LeftHand",
    "RightShoulder",
    "RightArm",
    "RightForeArm",
    "RightHand",
)
"""The joints of every LAFAN1 take's skeleton, in file order."""


def missing_lafan_joints(names: list[str]) -> list[str]:
    """The LAFAN1 joints a skeleton of joints `names` lacks."""
    return [joint for joint in LAFAN_JOINTS if joint not in names]
