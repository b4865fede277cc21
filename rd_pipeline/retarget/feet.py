"""Foot targets: planted where the human foot is, flat or tilted as it is; in swing, the human path
bent to leave and land on the plants, lifted clear of the floor."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from rd_pipeline.motion.contact import contact_runs
from rd_pipeline.retarget.config import PlantDrift, TargetShaping
from rd_pipeline.retarget.frames import yaw_and_pitch, yaw_pitch_frame
from rd_pipeline.retarget.smoothing import smoothstep
from rd_pipeline.robots import Robot


@dataclass(frozen=True)
class _Plant:
    """Frames [start, end) where the foot target stays at `point`."""

    start: int
    end: int
    point: np.ndarray
    """(3,) the planted position: the free target's first xy, the sole height."""


@dataclass(frozen=True)
class SoleFrames:
    """Where a foot learns how the human foot joint lies when its sole is flat on the floor."""

    trusted: tuple[np.ndarray, ...]
    """(T,) bool frames, in order of preference: the plants made in the first that has any teach it."""
    borrowed: Rotation | None = None
    """The other foot's lesson, taken where no trusted frame is planted: learnt on the same
    plants, the two feet's agree within a few degrees, while a foot's own kneeling plants would
    teach it upside down."""


@dataclass(frozen=True)
class _Swing:
    """Frames [start, end) between two plants (or a plant and an end of the clip)."""

    start: int
    end: int
    leaves: _Plant | None
    """The plant the foot lifts off from (None before the first plant)."""
    lands: _Plant | None
    """The plant the foot comes down on (None after the last plant)."""


def plant_foot(
    free: np.ndarray,
    forward: np.ndarray,
    human_rotation: np.ndarray,
    contact: np.ndarray,
    sole_vertices: np.ndarray,
    fps: float,
    pelvis_yaw: np.ndarray,
    yaw_range: tuple[float, float],
    human_path: np.ndarray,
    sole_frames: SoleFrames,
    shape: TargetShaping,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Rotation | None]:
    """Foot targets: fixed and flat while planted; in swing, the human path bent to meet the plants.
    Returns positions, rotations, the height the sole clears the floor by (0 while planted), the
    contact labels the plants were made from, and the sole's lesson if trusted frames taught it.

    A plant ends where the foot target has drifted `shape.plant_drift.target_m` from it while the
    human foot (`human_path`, scaled like the pelvis) has slid `plant_drift.human_m` (a shuffle
    step too low and slow to lift the contact label): a short swing carries the foot to a new plant.

    Swing orientation follows the human foot joint (its toe line is useless as a heading when the
    foot points down), through the constant offset that makes it flat and aligned during the plants
    made in `sole_frames`' trusted frames.
    """
    n = free.shape[0]
    drift = shape.plant_drift
    clearance = shape.swing_clearance_m
    sole = float(-sole_vertices[:, 2].min())
    half_swing = max(1, round(0.5 * drift.swing_s * fps))
    contact = _split_drifting_plants(contact, free, human_path, drift, half_swing)
    plants = _plants(contact, free, sole)
    heading = _planted_heading(forward, plants, pelvis_yaw, yaw_range)
    flat = Rotation.from_matrix(yaw_pitch_frame(heading, np.zeros(n)))
    swinging, lesson = _swing_orientation(human_rotation, flat, contact, sole_frames)
    flat = _keep_planted_tilt(flat, swinging, plants, shape.planted_tilt_rad)
    position = free.copy()
    for plant in plants:
        position[plant.start : plant.end] = plant.point
    lift = np.zeros(n)
    ramp = max(1, int(round(shape.swing_turn_time_s * fps)))
    rise = max(1, int(round(shape.swing_lift_time_s * fps)))
    for swing in _swings(plants, n):
        offsets = _swing_offsets(swing, free)
        if offsets is None:  # no contact in the whole clip: only keep feet above ground
            lift[:] = clearance
            continue
        frames = slice(swing.start, swing.end)
        position[frames] = _swing_path(free, swing, rise, offsets)
        since, until = _frames_from_plants(swing, n)
        lift[frames] = clearance * _eased_closeness(since, until, rise)
        weight = 1.0 - _eased_closeness(since, until, ramp)
        flat = _ease_to_plants(flat, swinging, swing, _nearest_plant_frame(swing, since, until), weight)
    rotation = flat.as_matrix()
    # The lowest point of the (possibly pitched) foot clears the floor by `lift`: a pointed toe
    # near the floor would otherwise drag along it.
    depth = -np.einsum("tj,vj->tv", rotation[:, 2], sole_vertices).min(axis=1)
    position[:, 2] = np.maximum(position[:, 2], lift + depth)
    return position, rotation, lift, contact, lesson


def _plants(contact: np.ndarray, free: np.ndarray, sole: float) -> list[_Plant]:
    """One plant per contact run, where the free target is when the run starts."""
    return [_Plant(start, end, np.array([*free[start, :2], sole])) for start, end in contact_runs(contact)]


def _planted_heading(
    forward: np.ndarray,
    plants: list[_Plant],
    pelvis_yaw: np.ndarray,
    yaw_range: tuple[float, float],
) -> np.ndarray:
    """(T,) foot heading: the human toe line's, held at one value per plant."""
    heading = np.unwrap(yaw_and_pitch(forward)[0])
    for plant in plants:
        run = slice(plant.start, plant.end)
        # A planted foot keeps one heading, within what the leg's vertical-axis joints can turn from
        # the pelvis (the H1's hip yaw only spans +-0.43 rad).
        relative = _wrap(np.mean(heading[run]) - np.mean(pelvis_yaw[run]))
        heading[run] = np.mean(pelvis_yaw[run]) + np.clip(relative, *yaw_range)
    return heading


def _swing_orientation(
    human_rotation: np.ndarray,
    flat: Rotation,
    contact: np.ndarray,
    sole: SoleFrames,
) -> tuple[Rotation, Rotation | None]:
    """The human foot turned by the one offset that best lays it on `flat` over the plants made in
    the first of `sole.trusted` that has any (kneeling, a planted foot may rest on its back), and
    that offset; without any, by the borrowed one, or learnt over all plants, and without plants
    over the whole clip (then no offset is returned)."""
    human = Rotation.from_matrix(human_rotation)
    for frames in sole.trusted:
        calibration = contact & frames
        if calibration.any():
            offset = (human[calibration].inv() * flat[calibration]).mean()
            return human * offset, offset
    if sole.borrowed is not None:
        return human * sole.borrowed, None
    calibration = contact if contact.any() else np.ones_like(contact)
    return human * (human[calibration].inv() * flat[calibration]).mean(), None


def _keep_planted_tilt(flat: Rotation, swinging: Rotation, plants: list[_Plant], tilt_limit: float) -> Rotation:
    """A foot planted on its toes or its instep (kneeling, crouching) keeps the human's tilt:
    laying it flat would lift the knees off the floor."""
    tilt = np.arccos(np.clip(swinging.as_matrix()[:, 2, 2], -1.0, 1.0))
    tilted = smoothstep((tilt - tilt_limit) / tilt_limit)  # eases in over one more `tilt_limit`
    for plant in plants:
        run = slice(plant.start, plant.end)
        if tilted[run].any():
            delta = (flat[run].inv() * swinging[run]).as_rotvec()
            flat = _assign(flat, run, flat[run] * Rotation.from_rotvec(delta * tilted[run, None]))
    return flat


def _swings(plants: list[_Plant], n: int) -> list[_Swing]:
    """The non-empty stretches before, between and after the plants, in time order."""
    edges = [0] + [x for plant in plants for x in (plant.start, plant.end)] + [n]
    swings = []
    for i in range(len(plants) + 1):
        leaves = plants[i - 1] if i > 0 else None
        lands = plants[i] if i < len(plants) else None
        if edges[2 * i + 1] > edges[2 * i]:
            swings.append(_Swing(edges[2 * i], edges[2 * i + 1], leaves, lands))
    return swings


def _swing_offsets(swing: _Swing, free: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """How far the free path misses the plant the swing leaves and the one it lands on; where
    one plant is missing the other's offset stands for both, and with neither there is none.

    Adding a blend of the two to the swing makes the foot leave and land exactly where it is planted.
    """
    if swing.leaves is not None and swing.lands is not None:
        return swing.leaves.point - free[swing.start - 1], swing.lands.point - free[swing.end]
    if swing.leaves is not None:
        before = swing.leaves.point - free[swing.start - 1]
        return before, before
    if swing.lands is not None:
        after = swing.lands.point - free[swing.end]
        return after, after
    return None


def _swing_path(
    free: np.ndarray,
    swing: _Swing,
    rise: int,
    offsets: tuple[np.ndarray, np.ndarray],
) -> np.ndarray:
    """The swing's positions: the free path, time-warped so the horizontal travel happens between
    the rise and the descent (a robot foot near the floor must not slide), plus the plant offsets."""
    a = swing.start
    b = swing.end
    t = np.arange(a, b)
    hold = min(rise, (b - a) // 3)
    lo = a - 1 if swing.leaves is not None else a
    hi = b if swing.lands is not None else b - 1
    warp = lo + (hi - lo) * np.clip((t - lo - hold) / max(hi - lo - 2 * hold, 1), 0.0, 1.0)
    path = np.stack([np.interp(warp, np.arange(len(free)), free[:, k]) for k in range(3)], axis=1)
    s = smoothstep(np.clip((warp - lo) / max(hi - lo, 1), 0.0, 1.0))
    return path + (1.0 - s)[:, None] * offsets[0] + s[:, None] * offsets[1]


def _frames_from_plants(swing: _Swing, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Frames since the plant left and until the plant landed on (`n`, farther than any, where
    there is none)."""
    t = np.arange(swing.start, swing.end)
    since = t - swing.start + 1 if swing.leaves is not None else np.full(len(t), n)
    until = swing.end - t if swing.lands is not None else np.full(len(t), n)
    return since, until


def _eased_closeness(since: np.ndarray, until: np.ndarray, frames: int) -> np.ndarray:
    """0 at a plant, easing to 1 once the nearer plant is `frames` away."""
    return smoothstep(np.clip(np.minimum(since, until) / frames, 0.0, 1.0))


def _nearest_plant_frame(swing: _Swing, since: np.ndarray, until: np.ndarray) -> np.ndarray:
    """Per swing frame, the frame of the nearer plant (its last or its first planted frame)."""
    if swing.leaves is not None and swing.lands is not None:
        return np.where(since <= until, swing.start - 1, swing.end)
    return np.full(len(since), swing.start - 1 if swing.leaves is not None else swing.end)


def _ease_to_plants(
    flat: Rotation,
    swinging: Rotation,
    swing: _Swing,
    nearest: np.ndarray,
    weight: np.ndarray,
) -> Rotation:
    """`flat` with the swing's frames set to the swinging orientation, eased by `weight` toward
    the flat orientation of the nearest plant."""
    frames = slice(swing.start, swing.end)
    flat_near = flat[np.clip(nearest, 0, len(flat) - 1)]
    delta = (swinging[frames].inv() * flat_near).as_rotvec()
    blended = swinging[frames] * Rotation.from_rotvec(delta * weight[:, None])
    return _assign(flat, frames, blended)


def _split_drifting_plants(
    contact: np.ndarray,
    free: np.ndarray,
    path: np.ndarray,
    drift: PlantDrift,
    gap: int,
) -> np.ndarray:
    """Contact with a swing of 2 x `gap` frames cut into every plant the foot drifts out of.

    Both the target (the scaled limb chain, which decides what the leg can reach) and the human
    foot must have moved: the chain alone drifts while a still human foot pivots under a lunge.
    """
    contact = contact.copy()
    for start, end in contact_runs(contact.copy()):
        anchor = free[start, :2]
        human = path[start, :2]
        t = start
        while t < end:
            drifted = np.linalg.norm(free[t, :2] - anchor) > drift.target_m
            moved = np.linalg.norm(path[t, :2] - human) > drift.human_m
            if drifted and moved and t - gap > start and t + gap < end:
                contact[t - gap : t + gap] = False
                anchor = free[t + gap, :2]
                human = path[t + gap, :2]
                start = t + gap
                t = start
            t += 1
    return contact


def _wrap(angle: float) -> float:
    return float((angle + np.pi) % (2 * np.pi) - np.pi)


def leg_yaw_range(robot: Robot, foot: str) -> tuple[float, float]:
    """How far the foot can turn about the vertical from the pelvis: summed ranges of the hinge
    joints between them whose axis is vertical in the rest pose (read from the model)."""
    model = robot.model
    data = mujoco.MjData(model)
    data.qpos[3] = 1.0
    mujoco.mj_kinematics(model, data)
    low = high = 0.0
    body = robot.body_ids[foot]
    while body > 0 and model.body_jntnum[body] >= 0:
        for joint in range(model.body_jntadr[body], model.body_jntadr[body] + model.body_jntnum[body]):
            if model.jnt_type[joint] != mujoco.mjtJoint.mjJNT_HINGE:
                continue
            axis = data.xaxis[joint]
            if abs(axis[2]) > 0.9:
                lo, hi = sorted(model.jnt_range[joint] * np.sign(axis[2]))
                low += lo
                high += hi
        body = model.body_parentid[body]
    return low, high


def _assign(rotations: Rotation, where: slice, values: Rotation) -> Rotation:
    quats = rotations.as_quat()
    quats[where] = values.as_quat()
    return Rotation.from_quat(quats)
