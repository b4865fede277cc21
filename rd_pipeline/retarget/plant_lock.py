"""Planted feet held still: each planted foot stays where it landed, moved by its leg's joints.

The refinements before this pass trade the planted foot against a posture and a pelvis that
move: on floor work the foot stays within millimetres of its target but jitters about it, and
the skate ruler reads that jitter as sliding. Here a foot that lands is held, frame by frame, over
the point where it landed, by a few damped least-squares steps of that leg's joints. Where the
leg cannot hold it (a joint at its stop: on floor work, H1's one-joint ankle), the pelvis gives a
little sideways as well; the gives are smoothed into one motion of the pelvis and the legs hold
the feet again under it. Where even that cannot reach the point (a range limit, a velocity
limit) the foot slides only as far as it must, and is held from there on.

Only the horizontal position is held, which is what slides; the foot's height stays the earlier
passes', which kept every body above the floor. A foot that rolls over on the floor (from its sole
onto its toes or its back, kneeling or crawling) must rise as it turns, or it goes into the floor:
held at its landing height as well, floor-work plants slid more and the whole robot had to be
lifted back out of the floor afterwards (`docs/studies/floor_work.md`, stage 25)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d

from rd_pipeline.retarget.collision import eased_until_clear
from rd_pipeline.retarget.config import IkConfig, PlantLockConfig
from rd_pipeline.retarget.quality import colliding_frames
from rd_pipeline.retarget.smoothing import smoothstep
from rd_pipeline.robots import Robot
from rd_pipeline.robots.model import leg_joints


@dataclass
class _Hold:
    """Where one foot is held, and for how many frames it has been released."""

    point: np.ndarray
    released: int = 0


def lock_plants(
    robot: Robot,
    qpos: np.ndarray,
    contact: np.ndarray,
    fps: float,
    settings: PlantLockConfig,
    ik: IkConfig,
) -> np.ndarray:
    """`qpos` (T, nq) with every planted foot (`contact` (T, 2), one column per foot body) held
    where it landed. Joints stay within the retarget range and within `ik`'s share of their
    velocity limits from the previous frame; no body pair goes deeper than `ik`'s hard limit where
    `qpos` kept it clear.

    Where a leg cannot hold its foot (a joint at its stop), the pelvis gives up to
    `settings.pelvis_give_m` sideways; the gives are smoothed into one shift of the pelvis, and
    the legs hold the feet again under it."""
    if settings.iterations == 0:
        return qpos
    held, gave = _hold_plants(robot, qpos, contact, fps, settings, ik, settings.pelvis_give_m)
    if gave.any():
        sigma = settings.pelvis_give_smoothing_s * fps
        shift = gaussian_filter1d(held[:, :2] - qpos[:, :2], sigma, axis=0, mode="nearest")
        moved = qpos.copy()
        moved[:, :2] += shift
        held, _ = _hold_plants(robot, moved, contact, fps, settings, ik, give_m=0.0)
    return clear_pairs(robot, qpos, held, ik.pair_depth_limit_m)


def _hold_plants(
    robot: Robot,
    qpos: np.ndarray,
    contact: np.ndarray,
    fps: float,
    settings: PlantLockConfig,
    ik: IkConfig,
    give_m: float,
) -> tuple[np.ndarray, np.ndarray]:
    """`qpos` with the planted feet held, frame by frame, and (T,) the frames where the pelvis
    moved (up to `give_m` sideways) because a leg could not hold its foot."""
    model = robot.model
    data = mujoco.MjData(model)
    feet = [robot.body_ids[foot] for foot in robot.config.foot_bodies]
    chains = leg_chains(robot)
    free = _foot_positions(model, data, qpos, feet)
    max_step = robot.config.velocity_limit / fps * ik.velocity_margin
    release = max(1, round(settings.release_s * fps))
    lower, upper = robot.retarget_range.T
    joints = robot.qpos_indices
    holds: list[_Hold | None] = [None] * len(feet)
    out = qpos.copy()
    gave = np.zeros(len(qpos), dtype=bool)
    for t in range(len(qpos)):
        low = lower
        high = upper
        if t > 0:
            # Frames after a held one come back to the earlier passes' pose within the joints'
            # velocity, like the frames they follow.
            low = np.maximum(lower, out[t - 1, joints] - max_step)
            high = np.minimum(upper, out[t - 1, joints] + max_step)
            out[t, joints] = np.clip(out[t, joints], low, high)
        goals = {}
        for k in range(len(feet)):
            holds[k] = _update_hold(holds[k], bool(contact[t, k]), free[t, k], release)
            hold = holds[k]
            if hold is not None:
                goals[k] = _goal(hold, free[t, k], release, settings.reach_m)
        reached = {
            k: reach(robot, data, out[t], goal, feet[k], chains[k], (low, high), settings) for k, goal in goals.items()
        }
        short = [k for k in goals if contact[t, k] and _horizontal(reached[k] - goals[k]) > settings.slip_m]
        if short and give_m > 0:
            pelvis = (qpos[t, :2] - give_m, qpos[t, :2] + give_m)
            reached = _reach_with_pelvis(robot, data, out[t], goals, feet, chains, (low, high), pelvis, settings)
            gave[t] = True
        for k, hold in enumerate(holds):
            # Out of reach, the foot slides as far as it must and is held from there.
            if hold is not None and contact[t, k] and _horizontal(reached[k] - hold.point) > settings.slip_m:
                hold.point = reached[k]
    return out, gave


def leg_chains(robot: Robot) -> list[np.ndarray]:
    """Each foot's leg joints, as indices into the config's joints (left, right)."""
    names = robot.config.joint_names
    return [np.array([names.index(j) for j in leg_joints(robot, (foot,))]) for foot in robot.config.foot_bodies]


def clear_pairs(robot: Robot, free: np.ndarray, held: np.ndarray, depth_m: float) -> np.ndarray:
    """`held`, eased back towards `free` a quarter at a time in the frames where holding a foot
    took a configured body pair (a knee into the other leg) deeper than `depth_m`."""
    changed = np.flatnonzero(np.any(held != free, axis=1))
    colliding = changed[colliding_frames(robot, held[changed], depth_m)]
    for t in colliding[~colliding_frames(robot, free[colliding], depth_m)]:
        held[t] = eased_until_clear(robot, held[t], free[t], depth_m)
    return held


def _update_hold(hold: _Hold | None, planted: bool, free: np.ndarray, release: int) -> _Hold | None:
    """A foot that lands is held where it is; one that lifts is released over `release` frames."""
    if planted:
        if hold is None or hold.released > 0:
            return _Hold(free.copy())
        return hold
    if hold is None:
        return None
    hold.released += 1
    return hold if hold.released <= release else None


def _goal(hold: _Hold, free: np.ndarray, release: int, reach_m: float) -> np.ndarray:
    """Where the foot goes this frame: over the held point at the height the foot has without the
    hold, at most `reach_m` from where it would be, easing back to that after a release."""
    pull = hold.point - free
    pull[2] = 0.0
    length = float(np.linalg.norm(pull))
    weight = 1.0 - smoothstep(np.asarray(hold.released / release))
    return free + pull * float(weight) * min(1.0, reach_m / max(length, 1e-9))


@dataclass(frozen=True)
class Turn:
    """How a foot should stay turned while `reach` moves it."""

    quat: np.ndarray
    """The orientation to keep (wxyz)."""
    weight_m: float
    """Metres of position error one radian of turn counts as."""


def reach(
    robot: Robot,
    data: mujoco.MjData,
    q: np.ndarray,
    goal: np.ndarray,
    foot: int,
    joints: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    settings: PlantLockConfig,
    turn: Turn | None = None,
) -> np.ndarray:
    """Move the leg `joints` of `q` (in place) towards putting `foot` on `goal`, and turned as
    `turn` says when given, within `bounds`. Returns where the foot ends."""
    model = robot.model
    jacobian = np.zeros((3 if turn is None else 6, model.nv))

    def error(trial: np.ndarray) -> np.ndarray:
        return _goal_error(model, data, trial, goal, foot, turn)

    def foot_jacobian() -> np.ndarray:
        if turn is None:
            mujoco.mj_jacBody(model, data, jacobian, None, foot)
        else:
            mujoco.mj_jacBody(model, data, jacobian[:3], jacobian[3:], foot)
            jacobian[3:] *= turn.weight_m
        return jacobian

    columns = _Columns(robot.qpos_indices[joints], robot.dof_indices[joints], bounds[0][joints], bounds[1][joints])
    _descend(model, data, q, columns, error, foot_jacobian, settings)
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    return data.xpos[foot].copy()


def _reach_with_pelvis(
    robot: Robot,
    data: mujoco.MjData,
    q: np.ndarray,
    goals: dict[int, np.ndarray],
    foot_bodies: list[int],
    chains: list[np.ndarray],
    bounds: tuple[np.ndarray, np.ndarray],
    pelvis: tuple[np.ndarray, np.ndarray],
    settings: PlantLockConfig,
) -> dict[int, np.ndarray]:
    """Move both legs and the pelvis's horizontal position of `q` (in place) towards putting each
    foot of `goals` (foot index -> goal) on its goal, the legs (`chains`, one per foot body of
    `foot_bodies`) within `bounds`, the pelvis within `pelvis` (low, high). Returns where each
    foot ends."""
    model = robot.model
    feet = [foot_bodies[k] for k in goals]
    targets = np.concatenate(list(goals.values()))
    legs = np.concatenate([chains[k] for k in goals])
    jacobian = np.zeros((3, model.nv))

    def positions(trial: np.ndarray) -> np.ndarray:
        data.qpos[:] = trial
        mujoco.mj_kinematics(model, data)
        return data.xpos[feet].ravel()

    def feet_jacobian() -> np.ndarray:
        rows = []
        for foot in feet:
            mujoco.mj_jacBody(model, data, jacobian, None, foot)
            rows.append(jacobian.copy())
        return np.vstack(rows)

    # The floating base's first two position coordinates and velocity dofs are its horizontal
    # position in the world.
    columns = _Columns(
        np.concatenate([[0, 1], robot.qpos_indices[legs]]),
        np.concatenate([[0, 1], robot.dof_indices[legs]]),
        np.concatenate([pelvis[0], bounds[0][legs]]),
        np.concatenate([pelvis[1], bounds[1][legs]]),
    )
    _descend(model, data, q, columns, lambda trial: targets - positions(trial), feet_jacobian, settings)
    ends = positions(q).reshape(-1, 3)
    return {k: ends[i].copy() for i, k in enumerate(goals)}


@dataclass(frozen=True)
class _Columns:
    """The coordinates of a configuration a descent moves, and their bounds."""

    qpos: np.ndarray
    dofs: np.ndarray
    low: np.ndarray
    high: np.ndarray


def _descend(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    q: np.ndarray,
    columns: _Columns,
    error: Callable[[np.ndarray], np.ndarray],
    jacobian: Callable[[], np.ndarray],
    settings: PlantLockConfig,
) -> None:
    """Damped least-squares steps of `columns` of `q` (in place) towards a zero `error(q)`, whose
    `jacobian()` is read in the pose `data` holds; a step that leaves the error larger is halved,
    then not taken."""
    residual = error(q)
    best = float(np.linalg.norm(residual))
    for _ in range(settings.iterations):
        if best < settings.tolerance_m:
            break
        mujoco.mj_comPos(model, data)
        jac = jacobian()[:, columns.dofs]
        trial = q.copy()
        trial[columns.qpos] = _bounded_step(jac, residual, q[columns.qpos], (columns.low, columns.high), settings)
        trial_residual = error(trial)
        distance = float(np.linalg.norm(trial_residual))
        for _ in range(settings.step_halvings):
            if distance < best:
                break
            trial = 0.5 * (q + trial)
            trial_residual = error(trial)
            distance = float(np.linalg.norm(trial_residual))
        if distance >= best:
            break
        q[:] = trial
        best = distance
        residual = trial_residual


def _horizontal(offset: np.ndarray) -> float:
    """The horizontal length of `offset`."""
    return float(np.linalg.norm(offset[:2]))


def _goal_error(
    model: mujoco.MjModel, data: mujoco.MjData, q: np.ndarray, goal: np.ndarray, foot: int, turn: Turn | None
) -> np.ndarray:
    """The foot's position error from `goal` in `q` (which `data` then holds), followed by its
    turn error (world axes, radians times the weight) when `turn` is given."""
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    error = goal - data.xpos[foot]
    if turn is None:
        return error
    inverse = np.empty(4)
    mujoco.mju_negQuat(inverse, data.xquat[foot])
    difference = np.empty(4)
    mujoco.mju_mulQuat(difference, turn.quat, inverse)
    rotation = np.empty(3)
    mujoco.mju_quat2Vel(rotation, difference, 1.0)
    return np.concatenate([error, rotation * turn.weight_m])


def _bounded_step(
    jacobian: np.ndarray,
    error: np.ndarray,
    joints: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    settings: PlantLockConfig,
) -> np.ndarray:
    """`joints` after a damped least-squares step towards `error`: a joint the step would take
    past its bound is held at the bound and the step solved again with the others."""
    low, high = bounds
    out = np.clip(joints, low, high)
    moving = np.ones(len(joints), dtype=bool)
    while moving.any():
        residual = error - jacobian @ (out - joints)
        step = _damped_step(jacobian[:, moving], residual, settings.damping)
        step *= min(1.0, settings.max_step_rad / max(float(np.abs(step).max()), 1e-12))
        trial = out.copy()
        trial[moving] += step
        outside = (trial < low) | (trial > high)
        if not outside.any():
            return trial
        out[outside] = np.clip(trial, low, high)[outside]
        moving &= ~outside
    return out


def _foot_positions(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray, feet: list[int]) -> np.ndarray:
    """(T, feet, 3) the foot bodies' positions in each row of `qpos`."""
    positions = np.empty((len(qpos), len(feet), 3))
    for t, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        positions[t] = data.xpos[feet]
    return positions


def _damped_step(jacobian: np.ndarray, error: np.ndarray, damping: float) -> np.ndarray:
    """The least-norm joint step that moves the foot by `error`, damped near singular legs."""
    gram = jacobian @ jacobian.T + damping * np.eye(len(error))
    return jacobian.T @ np.linalg.solve(gram, error)
