"""Pelvis repair: stretches near the floor where the pelvis stayed above its target, solved again
with the pelvis held harder, and kept where the finished motion is better for it.

Held harder over whole clips, a pelvis that sat on the robot's hip housings came down, but the
posture it lay in carried into the get-up that followed and dragged the planted feet there. A
re-solve of the raised stretch alone, faded back into the first solve, leaves the rest of the
clip as it was; whether its feet slide more shows only once the passes after the IK have put
them back, so each window is finished, with a margin, before it is judged."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from rd_pipeline.retarget.config import PelvisRepair
from rd_pipeline.retarget.ik import RetargetIk
from rd_pipeline.retarget.quality import FootMeshes, QualityThresholds
from rd_pipeline.retarget.repair import RepairWindow, brings_contact, fade_into, padded_windows

Finish = Callable[[slice, tuple[np.ndarray, ...]], tuple[RetargetIk, list[np.ndarray]]]
"""Finishes each of several versions of the frames `slice` of the clip (smoothing, feet
refined, plants locked) with one IK over those frames alone; returns that IK and the finished
versions."""


def lower_raised_pelvis(
    ik: RetargetIk, qpos: np.ndarray, repair: PelvisRepair, finish: Finish
) -> tuple[np.ndarray, int]:
    """`qpos` with its raised stretches (`raised_frames`) re-solved where, finished, that lowers
    the pelvis, slides the feet no faster and brings no body pair into contact; and how many were."""
    if repair.gain == 1.0:
        return qpos, 0
    raised = raised_frames(ik, qpos, repair)
    windows = padded_windows(raised, ik.targets.fps, repair.padding_s, repair.rejoin_s)
    if not windows:
        return qpos, 0
    lag_limit = float(np.median(ik.keypoint_errors(qpos))) + ik.settings.catch_up_margin_m
    out = qpos.copy()
    lowered = 0
    for window in windows:
        span = slice(window.anchor + 1, window.rejoin_end + 1)
        candidate = _solve_lower(ik, out, window, lag_limit, repair)
        if brings_contact(ik, candidate, out[span]):
            continue
        if _finishes_better(ik, out, candidate, window, repair, finish):
            out[span] = candidate
            lowered += 1
    return out, lowered


def raised_frames(ik: RetargetIk, qpos: np.ndarray, repair: PelvisRepair) -> np.ndarray:
    """(T,) the scaled human hips are under `hips_below_m` and the pelvis is more than
    `raised_m` above its target."""
    near_floor = ik.targets.human_pelvis[:, 2] < repair.hips_below_m
    return near_floor & (pelvis_excess(ik, qpos) > repair.raised_m)


def pelvis_excess(ik: RetargetIk, qpos: np.ndarray) -> np.ndarray:
    """(T,) how far (m) the pelvis of each row of `qpos` is above its target."""
    config = ik.robot.config
    body = ik.robot.body_ids[config.root_body]
    root = ik.targets.bodies.index(config.root_body)
    heights = np.empty(len(qpos))
    for t, q in enumerate(qpos):
        ik.configuration.update(q)
        heights[t] = ik.configuration.data.xpos[body, 2]
    return heights - ik.targets.positions[:, root, 2]


def floor_skate(ik: RetargetIk, qpos: np.ndarray) -> float:
    """Mean horizontal speed (m/s) of the feet over the steps of `qpos` that end with the sole on
    the floor (under `QualityThresholds.ground_contact_height_m`, as the quality ruler counts
    stance). The ruler's own `sole_heights_and_speeds` wants a whole reference motion and takes
    central differences; this one takes forward differences over the rows it is given."""
    meshes = FootMeshes.from_robot(ik.robot)
    bodies = [ik.robot.body_ids[foot] for foot in meshes.body_names]
    positions = np.empty((len(qpos), 2, 3))
    quaternions = np.empty((len(qpos), 2, 4))
    for t, q in enumerate(qpos):
        ik.configuration.update(q)
        positions[t] = ik.configuration.data.xpos[bodies]
        quaternions[t] = ik.configuration.data.xquat[bodies]
    soles = meshes.lowest_z(positions, quaternions, meshes.body_names)
    speeds = np.linalg.norm(np.diff(positions[..., :2], axis=0), axis=-1) * ik.targets.fps
    on_floor = soles[1:] < QualityThresholds().ground_contact_height_m
    return float(speeds[on_floor].mean()) if on_floor.any() else 0.0


def _solve_lower(
    ik: RetargetIk, qpos: np.ndarray, window: RepairWindow, lag_limit: float, repair: PelvisRepair
) -> np.ndarray:
    """Frames after `anchor` up to `rejoin_end` solved forward again with the pelvis's position
    costs times `gain`, then cross-faded into `qpos` after `backward_start`."""
    root = ik.targets.bodies.index(ik.robot.config.root_body)
    first_costs = ik.position_costs
    # A new array, not an edit in place: the IK compares each frame's costs with those it applied.
    ik.position_costs = first_costs.copy()
    ik.position_costs[window.anchor + 1 : window.rejoin_end + 1, root] *= repair.gain
    resolved = np.empty((window.rejoin_end - window.anchor, qpos.shape[1]))
    previous = qpos[window.anchor]
    ik.configuration.update(previous)
    try:
        for k, t in enumerate(range(window.anchor + 1, window.rejoin_end + 1)):
            resolved[k] = ik.solve_frame(t, previous, ik.root_steps[t], lag_limit)
            previous = resolved[k]
    finally:
        ik.position_costs = first_costs
    return fade_into(qpos, resolved, window)


def _finishes_better(
    ik: RetargetIk,
    qpos: np.ndarray,
    candidate: np.ndarray,
    window: RepairWindow,
    repair: PelvisRepair,
    finish: Finish,
) -> bool:
    """Finished over the window and `judge_margin_s` around it, the candidate's pelvis is lower
    on the mean and its feet slide at most `skate_tolerance_m_s` faster than the first solve's."""
    margin = int(round(repair.judge_margin_s * ik.targets.fps))
    frames = slice(max(window.anchor + 1 - margin, 0), min(window.rejoin_end + 1 + margin, len(qpos)))
    with_candidate = qpos[frames].copy()
    with_candidate[window.anchor + 1 - frames.start : window.rejoin_end + 1 - frames.start] = candidate
    part, (first, lowered) = finish(frames, (qpos[frames], with_candidate))
    higher = np.maximum(pelvis_excess(part, first), 0.0).mean()
    lower = np.maximum(pelvis_excess(part, lowered), 0.0).mean()
    slide = floor_skate(part, lowered) - floor_skate(part, first)
    return bool(lower < higher and slide <= repair.skate_tolerance_m_s)
