"""The plant lock on the G1 model: a planted foot stays over where it landed under a pelvis that
jitters, at the height the earlier passes gave it, slides no farther than it must under a pelvis
that runs away, and lets go when it lifts; on legs that cannot move, the pelvis gives instead."""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable

import numpy as np

from rd_pipeline.retarget.config import IkConfig, PlantLockConfig
from rd_pipeline.retarget.plant_lock import lock_plants
from rd_pipeline.robots import Robot

FPS = 50.0


def _standing(robot: Robot, frames: int) -> np.ndarray:
    """(frames, nq) the default pose, pelvis 0.75 m up."""
    q = np.zeros(robot.model.nq)
    q[2] = 0.75
    q[3] = 1.0
    q[robot.qpos_indices] = robot.config.default_pos
    return np.tile(q, (frames, 1))


def _lock(robot: Robot, qpos: np.ndarray, contact: np.ndarray) -> np.ndarray:
    return lock_plants(robot, qpos, contact, FPS, PlantLockConfig(), IkConfig())


def _stiff_legged(robot: Robot) -> Robot:
    """A copy of `robot` whose leg joints can move a milliradian from the default pose: a leg at
    its stops, which cannot hold its foot."""
    model = copy.deepcopy(robot.model)
    for name, angle in zip(robot.config.joint_names, robot.config.default_pos):
        if "hip" in name or "knee" in name or "ankle" in name:
            model.jnt_range[model.joint(name).id] = (angle - 0.001, angle + 0.001)
    return dataclasses.replace(robot, model=model)


def test_a_planted_foot_stays_put_under_a_jittering_pelvis(
    g1: Robot, foot_positions: Callable[[Robot, np.ndarray], np.ndarray]
) -> None:
    qpos = _standing(g1, 50)
    # Sideways and fore-aft; a rising pelvis would straighten the default pose's legs.
    jitter = np.random.default_rng(0).uniform(-0.004, 0.004, size=(50, 2))
    qpos[:, :2] += jitter
    contact = np.ones((50, 2), dtype=bool)
    before = foot_positions(g1, qpos)
    after = foot_positions(g1, _lock(g1, qpos, contact))
    drift_before = np.linalg.norm(before - before[0], axis=-1).max()
    drift_after = np.linalg.norm(after - after[0], axis=-1).max()
    assert drift_before > 0.004
    assert drift_after < 0.0002


def test_a_planted_foot_keeps_the_height_the_earlier_passes_gave_it(
    g1: Robot, foot_positions: Callable[[Robot, np.ndarray], np.ndarray]
) -> None:
    """The pelvis rises 15 mm over the plant and jitters sideways: the feet rise with it (as a
    foot rolling onto its toes must, to stay out of the floor), and stay over where they landed."""
    qpos = _standing(g1, 50)
    qpos[:, :2] += np.random.default_rng(2).uniform(-0.004, 0.004, size=(50, 2))
    qpos[:, 2] += np.linspace(0.0, 0.015, 50)
    contact = np.ones((50, 2), dtype=bool)
    before = foot_positions(g1, qpos)
    after = foot_positions(g1, _lock(g1, qpos, contact))
    horizontal_drift = np.linalg.norm(after[..., :2] - after[0, :, :2], axis=-1).max()
    assert horizontal_drift < 0.0002
    assert np.abs(after[..., 2] - before[..., 2]).max() < 0.0005
    assert after[-1, :, 2].min() - after[0, :, 2].max() > 0.014


def test_the_lock_keeps_joint_ranges_and_velocities(
    g1: Robot, limit_breaches: Callable[[Robot, np.ndarray, float], tuple[int, int]]
) -> None:
    qpos = _standing(g1, 50)
    qpos[:, :3] += np.random.default_rng(1).uniform(-0.004, 0.004, size=(50, 3))
    locked = _lock(g1, qpos, np.ones((50, 2), dtype=bool))
    assert limit_breaches(g1, locked, FPS) == (0, 0)


def test_a_foot_the_pelvis_drags_slides_only_past_the_reach(
    g1: Robot, foot_positions: Callable[[Robot, np.ndarray], np.ndarray]
) -> None:
    qpos = _standing(g1, 100)
    qpos[:, 0] += np.linspace(0.0, 0.10, 100)  # the pelvis walks 10 cm forward
    contact = np.ones((100, 2), dtype=bool)
    before = foot_positions(g1, qpos)
    after = foot_positions(g1, _lock(g1, qpos, contact))
    # Held while the earlier pose is within reach, then carried along at the reach.
    reach = PlantLockConfig().reach_m
    assert np.abs(after[:15, :, 0] - after[0, :, 0]).max() < 0.001
    assert np.abs(after[-1, :, 0] - before[-1, :, 0] + reach).max() < 0.002


def test_a_lifted_foot_is_released_over_the_release_time(
    g1: Robot, foot_positions: Callable[[Robot, np.ndarray], np.ndarray]
) -> None:
    qpos = _standing(g1, 60)
    qpos[:, 1] += 0.01 * np.sin(np.arange(60) / 3.0)  # the pelvis sways sideways
    contact = np.ones((60, 2), dtype=bool)
    contact[30:, 0] = False  # the left foot lifts at frame 30
    before = foot_positions(g1, qpos)
    after = foot_positions(g1, _lock(g1, qpos, contact))
    release = round(PlantLockConfig().release_s * FPS)
    assert np.linalg.norm(after[29, 0] - after[0, 0]) < 0.001
    assert np.linalg.norm(after[30 + release :, 0] - before[30 + release :, 0], axis=-1).max() < 0.0005
    assert np.linalg.norm(after[30:, 1] - after[0, 1], axis=-1).max() < 0.001


def test_where_the_legs_cannot_hold_the_feet_the_pelvis_gives(
    g1: Robot, foot_positions: Callable[[Robot, np.ndarray], np.ndarray]
) -> None:
    """The pelvis sways 1 cm sideways over two seconds on legs that cannot move: the legs alone
    let the feet sway with it; with the pelvis's give the feet stay within 2 mm of where they
    landed, and the pelvis stays put."""
    stiff = _stiff_legged(g1)
    qpos = _standing(stiff, 100)
    qpos[:, 1] += 0.01 * np.sin(np.arange(100) * np.pi / 50.0)
    contact = np.ones((100, 2), dtype=bool)
    legs_alone = dataclasses.replace(PlantLockConfig(), pelvis_give_m=0.0)
    swayed = foot_positions(stiff, lock_plants(stiff, qpos, contact, FPS, legs_alone, IkConfig()))
    given = lock_plants(stiff, qpos, contact, FPS, PlantLockConfig(), IkConfig())
    held = foot_positions(stiff, given)
    assert np.abs(swayed[..., 1] - swayed[0, :, 1]).max() > 0.009
    assert np.abs(held[..., 1] - held[0, :, 1]).max() < 0.002
    assert np.abs(given[:, 1] - given[0, 1]).max() < 0.002
