"""Foot targets: planted where the human foot is, flat or tilted as it is; in swing, the human path
bent to leave and land on the plants, lifted clear of the floor."""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from rd_pipeline.motion.contact import contact_runs
from rd_pipeline.retarget.config import PlantDrift
from rd_pipeline.retarget.frames import yaw_and_pitch, yaw_pitch_frame
from rd_pipeline.retarget.smoothing import smoothstep
from rd_pipeline.robots import Robot


def plant_foot(
    free: np.ndarray,
    forward: np.ndarray,
    human_rotation: np.ndarray,
    contact: np.ndarray,
    sole_vertices: np.ndarray,
    fps: float,
    clearance: float,
    lift_time_s: float,
    pelvis_yaw: np.ndarray,
    yaw_range: tuple[float, float],
    tilt_limit: float,
    drift: PlantDrift,
    human_path: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Foot targets: fixed and flat while planted; in swing, the human path bent to meet the plants.
    Returns positions, rotations, the height the sole clears the floor by (0 while planted) and
    the contact labels the plants were made from.

    A plant ends where the foot target has drifted `drift.target_m` from it while the human foot
    (`human_path`, scaled like the pelvis) has slid `drift.human_m` (a shuffle step too low and
    slow to lift the contact label): a short swing carries the foot to a new plant.

    Swing orientation follows the human foot joint (its toe line is useless as a heading when the
    foot points down), through the constant offset that makes it flat and aligned during plants.
    """
    n = free.shape[0]
    sole = float(-sole_vertices[:, 2].min())
    heading = np.unwrap(yaw_and_pitch(forward)[0])
    position = free.copy()
    planted_weight = np.zeros(n)
    lift = np.zeros(n)
    anchors = []
    half_swing = max(1, round(0.5 * drift.swing_s * fps))
    contact = _split_drifting_plants(contact, free, human_path, drift, half_swing)
    for start, end in contact_runs(contact):
        anchors.append((start, end, np.array([*free[start, :2], sole])))
        position[start:end] = anchors[-1][2]
        # A planted foot keeps one heading, within what the leg's vertical-axis joints can turn from
        # the pelvis (the H1's hip yaw only spans +-0.43 rad).
        relative = _wrap(np.mean(heading[start:end]) - np.mean(pelvis_yaw[start:end]))
        heading[start:end] = np.mean(pelvis_yaw[start:end]) + np.clip(relative, *yaw_range)
        planted_weight[start:end] = 1.0
    flat = Rotation.from_matrix(yaw_pitch_frame(heading, np.zeros(n)))
    human = Rotation.from_matrix(human_rotation)
    calibration = contact if contact.any() else np.ones(n, dtype=bool)
    offset = (human[calibration].inv() * flat[calibration]).mean()
    swinging = human * offset
    # A foot planted on its toes or its instep (kneeling, crouching) keeps the human's tilt: laying
    # it flat would lift the knees off the floor.
    tilt = np.arccos(np.clip(swinging.as_matrix()[:, 2, 2], -1.0, 1.0))
    tilted = smoothstep((tilt - tilt_limit) / tilt_limit)  # eases in over one more `tilt_limit`
    for start, end, _ in anchors:
        run = slice(start, end)
        if tilted[run].any():
            delta = (flat[run].inv() * swinging[run]).as_rotvec()
            flat = _assign(flat, run, flat[run] * Rotation.from_rotvec(delta * tilted[run, None]))
    # Swing: add a correction that blends from the previous plant's offset to the next one's, so
    # the foot leaves and lands exactly where it is planted. A robot foot near the floor must not
    # slide: it first rises to `clearance`, then travels, then comes down on its plant.
    ramp = max(1, int(round(0.1 * fps)))
    rise = max(1, int(round(lift_time_s * fps)))
    edges = [0] + [x for start, end, _ in anchors for x in (start, end)] + [n]
    for i in range(len(anchors) + 1):
        a = edges[2 * i]
        b = edges[2 * i + 1]
        if b <= a:
            continue
        before = anchors[i - 1][2] - free[a - 1] if i > 0 else None
        after = anchors[i][2] - free[b] if i < len(anchors) else None
        if before is None and after is None:  # no contact in the whole clip: only keep feet above ground
            lift[:] = clearance
            continue
        before = after if before is None else before
        after = before if after is None else after
        t = np.arange(a, b)
        since = t - a + 1 if i > 0 else np.full(b - a, n)
        until = b - t if i < len(anchors) else np.full(b - a, n)
        # Horizontal travel happens between the rise and the descent (time-warped human path).
        hold = min(rise, (b - a) // 3)
        lo = a - 1 if i > 0 else a
        hi = b if i < len(anchors) else b - 1
        warp = lo + (hi - lo) * np.clip((t - lo - hold) / max(hi - lo - 2 * hold, 1), 0.0, 1.0)
        path = np.stack([np.interp(warp, np.arange(n), free[:, k]) for k in range(3)], axis=1)
        s = smoothstep(np.clip((warp - lo) / max(hi - lo, 1), 0.0, 1.0))
        position[a:b] = path + (1.0 - s)[:, None] * before + s[:, None] * after
        lift[a:b] = clearance * smoothstep(np.clip(np.minimum(since, until) / rise, 0.0, 1.0))
        planted_weight[a:b] = 1.0 - smoothstep(np.clip(np.minimum(since, until) / ramp, 0.0, 1.0))
        # Near a plant, ease toward that plant's flat orientation.
        nearest = np.where(since <= until, a - 1, b) if 0 < i < len(anchors) else np.full(b - a, a - 1 if i > 0 else b)
        flat_near = flat[np.clip(nearest, 0, n - 1)]
        delta = (swinging[a:b].inv() * flat_near).as_rotvec()
        swinging_blended = swinging[a:b] * Rotation.from_rotvec(delta * planted_weight[a:b, None])
        flat = _assign(flat, slice(a, b), swinging_blended)
    rotation = flat.as_matrix()
    # The lowest point of the (possibly pitched) foot clears the floor by `lift`: a pointed toe
    # near the floor would otherwise drag along it.
    depth = -np.einsum("tij,vj->tvi", rotation, sole_vertices)[..., 2].min(axis=1)
    position[:, 2] = np.maximum(position[:, 2], lift + depth)
    return position, rotation, lift, contact


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
