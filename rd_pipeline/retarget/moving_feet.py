"""Feet that travel between plants kept off the floor, lifted by their legs.

The robot's foot trails a fast swing target, so it reaches the floor while it still travels to
where it will be held, and leaves the floor after it has started to travel: for those frames it is
dragged over the floor. Here such a foot is lifted, by its leg's joints alone, until its lowest
point clears the floor; where it travels stays as it was. So is a foot still travelling on the
first frame of its plant: it comes down on the plant a frame later, from above.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from rd_pipeline.retarget.config import IkConfig, MovingFootClearance, PlantLockConfig
from rd_pipeline.retarget.plant_lock import Turn, clear_pairs, leg_chains, reach
from rd_pipeline.retarget.quality import FootMeshes
from rd_pipeline.robots import Robot


def lift_moving_feet(
    robot: Robot,
    meshes: FootMeshes,
    qpos: np.ndarray,
    contact: np.ndarray,
    fps: float,
    settings: MovingFootClearance,
    lock: PlantLockConfig,
    ik: IkConfig,
) -> np.ndarray:
    """`qpos` (T, nq) with every foot (`meshes`) that is not planted (`contact` (T, 2)) and
    travels lifted to `settings.clearance_m`. A lifted frame stays within the retarget range and
    within `ik`'s share of the velocity limits from both its neighbours; `lock` sets the leg's
    steps."""
    if settings.clearance_m == 0:
        return qpos
    model = robot.model
    data = mujoco.MjData(model)
    feet = [robot.body_ids[foot] for foot in robot.config.foot_bodies]
    legs = [_Leg(foot, chain, vertices) for foot, chain, vertices in zip(feet, leg_chains(robot), meshes.vertices)]
    max_step = robot.config.velocity_limit / fps * ik.velocity_margin
    out = qpos.copy()
    # A lift that turns the foot a little moves it sideways, and a neighbouring frame on the
    # floor then travels: such frames are lifted in the next pass.
    airborne = ~contact.astype(bool)
    if settings.land_from_above:
        airborne |= _landings(contact)
    for _ in range(settings.passes):
        soles, xy = _soles_and_xy(model, data, out, feet, meshes)
        speed = np.linalg.norm(np.gradient(xy, 1.0 / fps, axis=0), axis=-1)
        dragged = (soles < settings.clearance_m) & (speed > settings.speed_m_s) & airborne
        for t, k in np.argwhere(dragged):
            bounds = _bounds(robot, out, t, max_step)
            path = xy[max(t - 1, 0), k], xy[min(t + 1, len(out) - 1), k]
            out[t] = _lifted(robot, data, out[t], legs[k], bounds, path, settings, lock)
    return clear_pairs(robot, qpos, out, ik.pair_depth_limit_m)


def _landings(contact: np.ndarray) -> np.ndarray:
    """(T, feet) the first frame of each plant after a swing."""
    planted = contact.astype(bool)
    out = np.zeros_like(planted)
    out[1:] = planted[1:] & ~planted[:-1]
    return out


@dataclass(frozen=True)
class _Leg:
    """One foot body, its leg's joints and its mesh points."""

    foot: int
    joints: np.ndarray
    vertices: np.ndarray


def _lifted(
    robot: Robot,
    data: mujoco.MjData,
    q: np.ndarray,
    leg: _Leg,
    bounds: tuple[np.ndarray, np.ndarray],
    path: tuple[np.ndarray, np.ndarray],
    settings: MovingFootClearance,
    lock: PlantLockConfig,
) -> np.ndarray:
    """`q` with `leg` moved so that its foot rises straight up, turning as little as the leg
    allows, until its sole clears the floor; `q` itself where the lift lowers an edge of the sole,
    or turns the foot off its `path` (where it is the frames before and after) so that it travels
    farther."""
    model = robot.model
    sole, xy = _sole_and_xy(model, data, q, leg.foot, leg.vertices)
    goal = data.xpos[leg.foot] + [0.0, 0.0, settings.clearance_m - sole]
    turn = Turn(data.xquat[leg.foot].copy(), settings.turn_weight_m)
    lifted = q.copy()
    reach(robot, data, lifted, goal, leg.foot, leg.joints, bounds, lock, turn)
    new_sole, new_xy = _sole_and_xy(model, data, lifted, leg.foot, leg.vertices)
    if new_sole > sole and _travel(path, new_xy) <= _travel(path, xy) + settings.detour_m:
        return lifted
    return q


def _travel(path: tuple[np.ndarray, np.ndarray], xy: np.ndarray) -> float:
    """Horizontal distance from where the foot was to `xy` and on to where it goes next."""
    return float(np.linalg.norm(xy - path[0]) + np.linalg.norm(path[1] - xy))


def _bounds(robot: Robot, qpos: np.ndarray, t: int, max_step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joint bounds of frame `t`: the retarget range, within a velocity step of both neighbours,
    widened to the frame's own angles (the lift never moves a joint back into bounds the earlier
    passes left it outside of: that would move the foot)."""
    low, high = robot.retarget_range.T
    joints = robot.qpos_indices
    for n in (t - 1, t + 1):
        if 0 <= n < len(qpos):
            low = np.maximum(low, qpos[n, joints] - max_step)
            high = np.minimum(high, qpos[n, joints] + max_step)
    own = qpos[t, joints]
    return np.minimum(low, own), np.maximum(high, own)


def _sole_and_xy(
    model: mujoco.MjModel, data: mujoco.MjData, q: np.ndarray, foot: int, vertices: np.ndarray
) -> tuple[float, np.ndarray]:
    """The lowest point of `foot`'s mesh `vertices` in `q`, and its body's horizontal position."""
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    return _sole(data, foot, vertices), data.xpos[foot, :2].copy()


def _sole(data: mujoco.MjData, foot: int, vertices: np.ndarray) -> float:
    """The lowest world z of `foot`'s mesh `vertices` in the pose `data` holds."""
    up = data.xmat[foot].reshape(3, 3)[2]
    return float(data.xpos[foot, 2] + (vertices @ up).min())


def _soles_and_xy(
    model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray, feet: list[int], meshes: FootMeshes
) -> tuple[np.ndarray, np.ndarray]:
    """(T, 2) each foot's lowest mesh point and (T, 2, 2) its body's horizontal position."""
    soles = np.empty((len(qpos), len(feet)))
    xy = np.empty((len(qpos), len(feet), 2))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for k, foot in enumerate(feet):
            soles[t, k] = _sole(data, foot, meshes.vertices[k])
        xy[t] = data.xpos[feet, :2]
    return soles, xy
