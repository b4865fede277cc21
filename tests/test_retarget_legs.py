"""Leg shaping: how far the body is lowered where a leg is too short for its foot.

Hand-built targets for one leg (the other stands straight under its hip, in reach), constant over
a second, so the smooth cover of the drop equals the per-frame requirement.
"""

from __future__ import annotations

import numpy as np
import pytest

from rd_pipeline.retarget.legs import keep_legs_reachable

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
