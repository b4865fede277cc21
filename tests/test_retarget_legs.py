"""Leg shaping: how far the body is lowered where a leg is too short for its foot.

Hand-built targets for one leg (the other stands straight under its hip, in reach), constant over
a second, so the smooth cover of the drop equals the per-frame requirement; then the real take
where lowering went wrong.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import LAFAN_DIR

from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, human_motion_from_bvh
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.legs import keep_legs_reachable
from rd_pipeline.retarget.quality import FootMeshes
from rd_pipeline.retarget.targets import build_targets
from rd_pipeline.robots import load_robot

FPS = 50.0
FRAMES = 50
REST_LEG_M = 0.6
"""Hip-to-foot distance of the rest pose (a straight leg)."""
FRACTION = 0.97
REACH_M = FRACTION * REST_LEG_M
SMOOTHING_S = 0.1


def _lowered(hip_offset: tuple[float, float, float]) -> dict[str, np.ndarray]:
    """Targets after `keep_legs_reachable`, the left hip at `hip_offset` from its foot on the floor."""
    rest = {
        "LeftUpLeg": np.array([0.0, 0.1, REST_LEG_M]),
        "LeftFoot": np.array([0.0, 0.1, 0.0]),
        "RightUpLeg": np.array([0.0, -0.1, REST_LEG_M]),
        "RightFoot": np.array([0.0, -0.1, 0.0]),
    }
    left_hip = np.array(hip_offset)
    points = {
        "Hips": left_hip + [0.0, -0.1, 0.05],
        "LeftUpLeg": left_hip,
        "LeftLeg": 0.5 * left_hip,
        "LeftFoot": np.zeros(3),
        "RightUpLeg": left_hip + [0.0, -0.2, 0.0],
        "RightLeg": left_hip + [0.0, -0.2, -0.25],
        "RightFoot": left_hip + [0.0, -0.2, -0.5],
        "LeftHand": left_hip + [0.3, 0.0, 0.2],
    }
    targets = {joint: np.tile(point, (FRAMES, 1)) for joint, point in points.items()}
    keep_legs_reachable(targets, rest, FPS, FRACTION, SMOOTHING_S)
    return {joint: targets[joint] - np.tile(points[joint], (FRAMES, 1)) for joint in points}


def test_a_leg_under_the_body_drops_it_by_the_whole_excess() -> None:
    moved = _lowered((0.0, 0.0, REACH_M + 0.1))
    np.testing.assert_allclose(moved["Hips"][:, 2], -0.1, atol=1e-9)
    np.testing.assert_allclose(moved["LeftHand"][:, 2], -0.1, atol=1e-9)
    np.testing.assert_allclose(moved["LeftLeg"][:, 2], -0.05, atol=1e-9)
    np.testing.assert_allclose(moved["LeftFoot"], 0.0)
    np.testing.assert_allclose(moved["Hips"][:, :2], 0.0)


def test_a_leg_in_reach_leaves_the_body_where_it_is() -> None:
    moved = _lowered((0.2, 0.0, 0.5))
    for joint, offset in moved.items():
        np.testing.assert_allclose(offset, 0.0, err_msg=joint)


def test_a_leg_stretched_along_the_floor_barely_lowers_the_body() -> None:
    """A lunge: the hip 0.3 m up and just inside the leg's horizontal reach. Lowering until the leg
    fits straight down would take the body 0.22 m down, hands and trunk into the floor."""
    moved = _lowered((REACH_M - 0.005, 0.0, 0.3))
    drop = -moved["Hips"][0, 2]
    length = np.hypot(REACH_M - 0.005, 0.3)
    assert drop == pytest.approx(0.3 * (1.0 - REACH_M / length), abs=1e-9)
    assert drop < 0.05


def test_the_drop_is_continuous_across_the_horizontal_reach() -> None:
    inside = -_lowered((REACH_M - 0.001, 0.0, 0.3))["Hips"][0, 2]
    outside = -_lowered((REACH_M + 0.001, 0.0, 0.3))["Hips"][0, 2]
    assert abs(inside - outside) < 1e-3


def test_a_body_lying_on_its_side_keeps_its_trunk_targets_above_the_floor() -> None:
    """fallAndGetUp3 62-70 s: the human lies on its left side, one leg stretched out, hips 0.09 m or
    more above the floor. Lowering straight down put the G1's pelvis target under the floor and its
    left hip 0.14 m under it."""
    human = human_motion_from_bvh(read_bvh(LAFAN_DIR / "fallAndGetUp3_subject1.bvh"), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
    frames = slice(int(62.0 * human.fps), int(70.0 * human.fps))
    human = dataclasses.replace(human, pos_w=human.pos_w[frames], quat_w=human.quat_w[frames])
    robot = load_robot("g1")
    params = RetargetConfig()
    feet = FootMeshes.from_robot(robot).vertices
    targets = build_targets(human, robot, params.fps, feet, params.contact, params.shape, params.body_contact)
    trunk = [targets.bodies.index(body) for body in ("pelvis", "left_hip_roll_link", "right_hip_roll_link")]
    assert targets.human_pelvis[:, 2].min() < 0.1, "the excerpt should lie on the floor"
    assert targets.positions[:, trunk, 2].min() > 0.0
