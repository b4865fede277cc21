"""Feet that travel between plants, on the G1 model: a foot dragged over the floor is lifted
straight up by its leg, and so is one on the frame it lands still travelling, while a planted
foot, a still foot and the rest of the pose stay."""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np
import pytest

from rd_pipeline.params import ParamRangeError
from rd_pipeline.retarget.config import IkConfig, MovingFootClearance, PlantLockConfig
from rd_pipeline.retarget.moving_feet import lift_moving_feet
from rd_pipeline.retarget.quality import FootMeshes
from rd_pipeline.robots import Robot
from rd_pipeline.robots.model import leg_joints

FPS = 50.0
FRAMES = 40


def _gliding(robot: Robot, speed_m_s: float) -> np.ndarray:
    """(FRAMES, nq) the default pose with its soles 5 mm up, the whole robot gliding forward."""
    q = np.zeros(robot.model.nq)
    q[3] = 1.0
    q[robot.qpos_indices] = robot.config.default_pos
    q[2] = 0.005 - _soles(robot, q[None])[0].min()
    qpos = np.tile(q, (FRAMES, 1))
    qpos[:, 0] += speed_m_s * np.arange(FRAMES) / FPS
    return qpos


def _soles(robot: Robot, qpos: np.ndarray) -> np.ndarray:
    """(T, 2) the lowest point of each foot."""
    meshes = FootMeshes.from_robot(robot)
    data = mujoco.MjData(robot.model)
    feet = [robot.body_ids[foot] for foot in robot.config.foot_bodies]
    out = np.empty((len(qpos), 2))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(robot.model, data)
        for k, foot in enumerate(feet):
            up = data.xmat[foot].reshape(3, 3)[2]
            out[t, k] = data.xpos[foot, 2] + (meshes.vertices[k] @ up).min()
    return out


def _lift(robot: Robot, qpos: np.ndarray, contact: np.ndarray, **settings: float) -> np.ndarray:
    clearance = MovingFootClearance(**settings)  # type: ignore[arg-type]
    meshes = FootMeshes.from_robot(robot)
    return lift_moving_feet(robot, meshes, qpos, contact, FPS, clearance, PlantLockConfig(), IkConfig())


def test_a_dragged_foot_rises_to_the_clearance_where_it_travels(
    g1: Robot, foot_positions: Callable[[Robot, np.ndarray], np.ndarray]
) -> None:
    qpos = _gliding(g1, 0.3)
    contact = np.zeros((FRAMES, 2), dtype=bool)
    contact[:, 1] = True  # the right foot is planted and glides along: not this pass's business
    lifted = _lift(g1, qpos, contact)
    soles = _soles(g1, lifted)
    clearance = MovingFootClearance().clearance_m
    assert _soles(g1, qpos)[:, 0].max() < 0.006
    assert soles[:, 0].min() > clearance - 0.001
    assert np.abs(foot_positions(g1, lifted) - foot_positions(g1, qpos))[..., :2].max() < 0.001
    names = g1.config.joint_names
    left_leg = g1.qpos_indices[[names.index(j) for j in leg_joints(g1, (g1.config.foot_bodies[0],))]]
    others = np.setdiff1d(np.arange(g1.model.nq), left_leg)
    assert np.array_equal(lifted[:, others], qpos[:, others])


def test_a_still_foot_stays_on_the_floor(g1: Robot) -> None:
    qpos = _gliding(g1, 0.03)  # slower than `speed_m_s`
    lifted = _lift(g1, qpos, np.zeros((FRAMES, 2), dtype=bool))
    assert np.array_equal(lifted, qpos)


def test_the_lift_keeps_joint_ranges_and_velocities(
    g1: Robot, limit_breaches: Callable[[Robot, np.ndarray, float], tuple[int, int]]
) -> None:
    qpos = _gliding(g1, 0.5)
    lifted = _lift(g1, qpos, np.zeros((FRAMES, 2), dtype=bool))
    assert limit_breaches(g1, lifted, FPS) == (0, 0)


def test_no_clearance_leaves_the_motion_as_it_is(g1: Robot) -> None:
    qpos = _gliding(g1, 0.3)
    assert _lift(g1, qpos, np.zeros((FRAMES, 2), dtype=bool), clearance_m=0.0) is qpos


def test_a_negative_clearance_is_refused_by_name() -> None:
    with pytest.raises(ParamRangeError, match="clearance_m"):
        MovingFootClearance(clearance_m=-0.01)


def test_a_foot_that_lands_travelling_comes_down_from_above(g1: Robot) -> None:
    """The left foot lands at frame 20 while the robot glides on: on its landing frame it is
    still in the air (it comes down on its plant instead of sliding into it), and from the next
    frame on it is left to the plant."""
    qpos = _gliding(g1, 0.3)
    contact = np.zeros((FRAMES, 2), dtype=bool)
    contact[20:, 0] = True
    contact[:, 1] = True
    landed = _soles(g1, _lift(g1, qpos, contact))
    slid_in = _soles(g1, _lift(g1, qpos, contact, land_from_above=False))
    clearance = MovingFootClearance().clearance_m
    assert landed[20, 0] > clearance - 0.001
    assert slid_in[20, 0] < 0.006
    assert landed[21:, 0].max() < 0.006
