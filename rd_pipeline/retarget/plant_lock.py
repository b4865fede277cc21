"""Planted feet held still: each planted foot stays where it landed, moved by its leg's joints.

The refinements before this pass trade the planted foot against a posture and a pelvis that
move: on floor work the foot stays within millimetres of its target but jitters about it, and
the skate ruler reads that jitter as sliding. Here a foot that lands is held, frame by frame, over
the point where it landed, by a few damped least-squares steps of that leg's joints alone. Where
the leg cannot reach the point (a range limit, a velocity limit) the foot slides only as far as
it must, and is held from there on.

Only the horizontal position is held, which is what slides; the foot's height stays the earlier
passes', which kept every body above the floor. A foot that rolls over on the floor (from its sole
onto its toes or its back, kneeling or crawling) must rise as it turns, or it goes into the floor:
held at its landing height as well, floor-work plants slid more and the whole robot had to be
lifted back out of the floor afterwards (`docs/studies/floor_work.md`, stage 25)."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

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
    `qpos` kept it clear."""
    if settings.iterations == 0:
        return qpos
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
    for t in range(len(qpos)):
        low = lower
        high = upper
        if t > 0:
            # Frames after a held one come back to the earlier passes' pose within the joints'
            # velocity, like the frames they follow.
            low = np.maximum(lower, out[t - 1, joints] - max_step)
            high = np.minimum(upper, out[t - 1, joints] + max_step)
            out[t, joints] = np.clip(out[t, joints], low, high)
        for k in range(len(feet)):
            holds[k] = _update_hold(holds[k], bool(contact[t, k]), free[t, k], release)
            hold = holds[k]
            if hold is None:
                continue
            goal = _goal(hold, free[t, k], release, settings.reach_m)
            reached = reach(robot, data, out[t], goal, feet[k], chains[k], (low, high), settings)
            # Out of reach, the foot slides as far as it must and is held from there.
            if contact[t, k] and np.linalg.norm((reached - hold.point)[:2]) > settings.slip_m:
                hold.point = reached
    return clear_pairs(robot, qpos, out, ik.pair_depth_limit_m)


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
    `turn` says when given, within `bounds`; a step that leaves the foot farther from its goal is
    halved, then not taken. Returns where the foot ends."""
    model = robot.model
    jacobian = np.zeros((3 if turn is None else 6, model.nv))
    columns = robot.qpos_indices[joints]
    limits = (bounds[0][joints], bounds[1][joints])
    error = _goal_error(model, data, q, goal, foot, turn)
    best = float(np.linalg.norm(error))
    for _ in range(settings.iterations):
        if best < settings.tolerance_m:
            break
        mujoco.mj_comPos(model, data)
        if turn is None:
            mujoco.mj_jacBody(model, data, jacobian, None, foot)
        else:
            mujoco.mj_jacBody(model, data, jacobian[:3], jacobian[3:], foot)
            jacobian[3:] *= turn.weight_m
        jac = jacobian[:, robot.dof_indices[joints]]
        trial = q.copy()
        trial[columns] = _bounded_step(jac, error, q[columns], limits, settings)
        trial_error = _goal_error(model, data, trial, goal, foot, turn)
        distance = float(np.linalg.norm(trial_error))
        for _ in range(settings.step_halvings):
            if distance < best:
                break
            trial = 0.5 * (q + trial)
            trial_error = _goal_error(model, data, trial, goal, foot, turn)
            distance = float(np.linalg.norm(trial_error))
        if distance >= best:
            break
        q[:] = trial
        best = distance
        error = trial_error
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    return data.xpos[foot].copy()


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
