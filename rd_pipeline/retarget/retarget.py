"""The retargeting pipeline: targets from the human, IK frame by frame, feet kept above the ground."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import binary_dilation, gaussian_filter1d

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.human import HumanMotion
from rd_pipeline.motion.reference import ReferenceMotion, reference_from_joint_trajectory
from rd_pipeline.retarget.collision import eased_until_clear
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.ik import RetargetIk
from rd_pipeline.retarget.moving_feet import lift_moving_feet
from rd_pipeline.retarget.pelvis_repair import lower_raised_pelvis
from rd_pipeline.retarget.plant_lock import lock_plants
from rd_pipeline.retarget.quality import FootMeshes, colliding_frames
from rd_pipeline.retarget.repair import repair_lag
from rd_pipeline.retarget.smoothing import blend_configurations, resample_configurations, smooth_cover
from rd_pipeline.retarget.targets import RetargetTargets, build_targets
from rd_pipeline.robots import Robot
from rd_pipeline.robots.hulls import BodyHulls


@dataclass(frozen=True)
class RetargetResult:
    """A retargeted motion and the targets it was solved for."""

    reference: ReferenceMotion
    """The robot reference motion."""
    targets: RetargetTargets
    """Scaled-human keypoint targets (for the keypoint error and for viewing)."""
    ground_lift_max_m: float
    """Largest lift the ground pass had to apply."""
    repaired_windows: int
    """Lagging stretches the lag repair re-solved."""


def retarget(
    human: HumanMotion,
    robot: Robot,
    params: RetargetConfig,
    track: Callable[[Iterable[int], int, str], Iterable[int]] = lambda frames, total, label: frames,
) -> RetargetResult:
    """Retarget `human` onto `robot` with `params`; `track` wraps the frame loops (progress bars,
    labelled by pass).

    Per-frame IK against the targets; stretches that fell far behind them solved again from both
    ends, and stretches near the floor where the pelvis stayed high solved again with it held
    harder (`pelvis_repair.py`); then a sequence-level pass: the whole trajectory is smoothed and the feet are put back on
    their targets by a leg-only IK that stays near the smoothed pose.
    """
    if not np.all(np.isfinite(human.pos_w)):
        frame = int(np.argwhere(~np.isfinite(human.pos_w))[0, 0])
        raise PipelineError(f"human motion has a non-finite position at frame {frame}")
    fps = params.fps
    settings = params.ik
    if human.duration_s < 1.0 / fps:
        raise PipelineError(f"clip of {human.duration_s:.4f} s is shorter than one frame period (1/{fps:g} s)")
    feet = FootMeshes.from_robot(robot)
    # With `solve_at_capture_rate` only the capture's own frames are solved (it holds nothing
    # between them, and every pass costs per frame), then resampled to the output rate.
    rate = min(human.fps, fps) if settings.solve_at_capture_rate else fps
    targets = build_targets(human, robot, rate, feet.vertices, params.contact, params.shape, params.body_contact)
    hulls = BodyHulls.from_robot(robot)
    ik = RetargetIk(robot, targets, params.weights, settings, hulls)
    qpos = ik.solve(track(range(targets.n_frames), targets.n_frames, "whole-body IK"))
    qpos, repaired = repair_lag(ik, qpos, params.repair)

    def finisher(frames: slice) -> tuple[RetargetIk, Callable[[np.ndarray], np.ndarray]]:
        part = RetargetIk(robot, targets.frames(frames), params.weights, settings, hulls)
        return part, lambda rows: _finish(part, rows, params, feet)

    qpos, _ = lower_raised_pelvis(ik, qpos, params.pelvis_repair, finisher)
    qpos = _finish(ik, qpos, params, feet, track)
    if rate != fps:
        targets = build_targets(human, robot, fps, feet.vertices, params.contact, params.shape, params.body_contact)
        qpos = _resampled(robot, qpos, rate, np.arange(targets.n_frames) / fps, settings.pair_depth_limit_m)
    reference = _reference(robot, qpos, targets)
    # The IK keeps every body above the floor; smoothing can still dip a body by a few millimetres.
    sink = hulls.sink_depth(reference.body_pos_w, reference.body_quat_w, reference.body_names)
    lift = smooth_cover(sink, fps, settings.ground_lift_smoothing_s)
    if lift.any():
        qpos[:, 2] += lift
        reference = _reference(robot, qpos, targets)
    return RetargetResult(
        reference=reference,
        targets=targets,
        ground_lift_max_m=float(lift.max()),
        repaired_windows=repaired,
    )


def _finish(
    ik: RetargetIk,
    qpos: np.ndarray,
    params: RetargetConfig,
    feet: FootMeshes,
    track: Callable[[Iterable[int], int, str], Iterable[int]] = lambda frames, total, label: frames,
) -> np.ndarray:
    """The passes after the IK: the trajectory smoothed, the feet put back on their targets by the
    legs (and the pelvis where they cannot), the plants locked and the moving feet lifted."""
    settings = ik.settings
    if settings.trajectory_smoothing_s <= 0:
        return qpos
    robot = ik.robot
    targets = ik.targets
    rate = targets.fps
    smoothed = _smooth_trajectory(robot, qpos, settings.trajectory_smoothing_s * rate)
    # Smoothing knows nothing of self-collision: where it brings a pair well inside the margin
    # the IK kept, ease back to the IK solution for those frames.
    clearance = settings.smoothed_pair_fraction * settings.collision_margin_m
    close = colliding_frames(robot, smoothed, -clearance)
    keep_ik = np.minimum(smooth_cover(close.astype(float), rate, settings.ik_blend_s), 1.0)
    qpos = blend_configurations(smoothed, qpos, keep_ik)
    refined = ik.refine_feet(qpos, track(range(targets.n_frames), targets.n_frames, "feet on the smoothed motion"))
    if settings.pelvis_slack_m > 0:
        refined = _pelvis_slack(ik, qpos, refined)
    qpos = lock_plants(robot, refined, targets.foot_contact, rate, params.plant_lock, settings)
    return lift_moving_feet(
        robot, feet, qpos, targets.foot_contact, rate, params.moving_feet, params.plant_lock, settings
    )


def _pelvis_slack(ik: RetargetIk, smoothed: np.ndarray, refined: np.ndarray) -> np.ndarray:
    """`refined` with the pelvis moved, smoothly, around the frames where the legs alone left a
    planted foot off its target (a knee or hip at its range limit), and the feet refined again there."""
    settings = ik.settings
    conflict = ik.planted_foot_misses(refined) > settings.pelvis_slack_trigger_m
    if not conflict.any():
        return refined
    sigma = settings.pelvis_slack_smoothing_s * ik.targets.fps
    # The smoothed moves spread over a few sigma: the pelvis may already move there.
    around = binary_dilation(conflict, iterations=max(1, round(2 * sigma)))
    reached = ik.refine_feet(smoothed, np.flatnonzero(around), root_slack_m=settings.pelvis_slack_m)
    shift = gaussian_filter1d(reached[:, :3] - smoothed[:, :3], sigma, axis=0, mode="nearest")
    moved = smoothed.copy()
    moved[:, :3] += shift
    # The pelvis moves here without the leg changes that let it: lying down, a lowered pelvis
    # takes a knee or the trunk into the floor, which the legs-only refinement could escape only
    # by a leg's jump in one frame. What the lowering sank, other than the feet the refinement
    # puts back on their targets, is raised back first.
    lowered = np.flatnonzero(shift[:, 2] < 0.0)
    bodies = ik.floor.hulls.without(ik.robot.config.foot_bodies)
    sunk = np.zeros(len(moved))
    sunk[lowered] = np.maximum(_sink(ik, moved, lowered, bodies) - _sink(ik, smoothed, lowered, bodies), 0.0)
    moved[:, 2] += smooth_cover(sunk, ik.targets.fps, settings.pelvis_slack_smoothing_s)
    changed = np.flatnonzero(np.any(moved[:, :3] != smoothed[:, :3], axis=1))
    return ik.refine_feet(moved, changed, start=refined)


def _sink(ik: RetargetIk, qpos: np.ndarray, rows: np.ndarray, hulls: BodyHulls) -> np.ndarray:
    """How far the deepest body reaches below the floor in each of `rows` of `qpos`."""
    robot = ik.robot
    reference = reference_from_joint_trajectory(
        robot,
        ik.targets.fps,
        qpos[rows, :3],
        qpos[rows, 3:7],
        qpos[rows][:, robot.qpos_indices],
        ik.targets.foot_contact[rows],
    )
    return hulls.sink_depth(reference.body_pos_w, reference.body_quat_w, reference.body_names)


def _resampled(robot: Robot, qpos: np.ndarray, rate: float, times: np.ndarray, depth_m: float) -> np.ndarray:
    """`qpos` (solved at `rate`) read at `times`; where a read pose brings a configured body pair
    deeper than `depth_m` into contact (a hand sweeping past the torso between two solved frames
    that both kept it clear), it is blended towards the nearest solved frame, a quarter at a time,
    until the pair is clear."""
    out = resample_configurations(qpos, rate, times)
    for j in np.flatnonzero(colliding_frames(robot, out, depth_m)):
        nearest = qpos[min(int(round(times[j] * rate)), len(qpos) - 1)]
        out[j] = eased_until_clear(robot, out[j], nearest, depth_m)
    return out


def _smooth_trajectory(robot: Robot, qpos: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian smoothing of the joint and root trajectories (sequence-level), back inside the range
    the IK kept (the config's retarget range).

    Smoothing averages neighbouring frames, so it never raises a frame-to-frame speed above the
    largest one it started from; the velocity limits the IK enforced still hold.
    """
    smoothed = gaussian_filter1d(qpos, sigma, axis=0, mode="nearest")
    quat = smoothed[:, 3:7]
    smoothed[:, 3:7] = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    lower, upper = robot.retarget_range.T
    smoothed[:, robot.qpos_indices] = np.clip(smoothed[:, robot.qpos_indices], lower, upper)
    return smoothed


def _reference(robot: Robot, qpos: np.ndarray, targets: RetargetTargets) -> ReferenceMotion:
    return reference_from_joint_trajectory(
        robot,
        targets.fps,
        qpos[:, :3].copy(),
        qpos[:, 3:7].copy(),
        qpos[:, robot.qpos_indices].copy(),
        targets.foot_contact,
    )
