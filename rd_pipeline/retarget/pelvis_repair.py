"""Pelvis repair: stretches near the floor where the pelvis stayed above its target, solved again
with the pelvis held harder, and kept where the finished motion is better for it.

Held harder over whole clips, a pelvis that sat on the robot's hip housings came down, but the
posture it lay in carried into the get-up that followed and dragged the planted feet there. A
re-solve of the raised stretch alone, faded back into the first solve, leaves the rest of the
clip as it was; whether its feet slide more shows only once the passes after the IK have put
them back, so each window is finished, with a margin, before it is judged. No one gain suits
every stretch, so each is tried at several, stiffest first; and a stretch the quality ruler
would read within its bar is left alone, for a re-solve and its judge cost as much as the whole
clip's IK."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rd_pipeline.retarget.config import PelvisRepair
from rd_pipeline.retarget.ik import RetargetIk
from rd_pipeline.retarget.quality import FootMeshes, QualityThresholds, pelvis_height_deviation
from rd_pipeline.retarget.repair import RepairWindow, brings_contact, fade_into, padded_windows

Finisher = Callable[[slice], tuple[RetargetIk, Callable[[np.ndarray], np.ndarray]]]
"""For the frames `slice` of the clip, an IK over those frames alone and the passes after the IK
(smoothing, feet refined, plants locked) that finish rows of them with it."""


def lower_raised_pelvis(
    ik: RetargetIk, qpos: np.ndarray, repair: PelvisRepair, finisher: Finisher
) -> tuple[np.ndarray, int]:
    """`qpos` with its raised stretches (`raised_frames`) re-solved where, finished, that lowers
    the pelvis, slides the feet no faster and brings no body pair into contact; and how many were."""
    if not repair.gains:
        return qpos, 0
    windows = _visible_windows(ik, qpos, repair)
    if not windows:
        return qpos, 0
    lag_limit = float(np.median(ik.keypoint_errors(qpos))) + ik.settings.catch_up_margin_m
    out = qpos.copy()
    lowered = 0
    for window in windows:
        kept = _stiffest_kept(ik, out, window, lag_limit, repair, finisher)
        if kept is not None:
            out[window.anchor + 1 : window.rejoin_end + 1] = kept
            lowered += 1
    return out, lowered


def _visible_windows(ik: RetargetIk, qpos: np.ndarray, repair: PelvisRepair) -> list[RepairWindow]:
    """The padded raised stretches with a frame somewhere in them that is `visibly_raised`."""
    raised = raised_frames(ik, qpos, repair)
    windows = padded_windows(raised, ik.targets.fps, repair.padding_s, repair.rejoin_s)
    visible = visibly_raised(ik, qpos, repair)
    return [window for window in windows if visible[window.anchor + 1 : window.rejoin_end + 1].any()]


def _stiffest_kept(
    ik: RetargetIk,
    qpos: np.ndarray,
    window: RepairWindow,
    lag_limit: float,
    repair: PelvisRepair,
    finisher: Finisher,
) -> np.ndarray | None:
    """The window re-solved at the first of `repair.gains` that brings no body pair into contact
    and that the judge keeps; None if none is."""
    span = slice(window.anchor + 1, window.rejoin_end + 1)
    judge = None
    for gain in repair.gains:
        candidate = _solve_lower(ik, qpos, window, lag_limit, gain)
        if brings_contact(ik, candidate, qpos[span]):
            continue
        if judge is None:
            # Built at the first candidate that needs it, once per window.
            judge = _WindowJudge.of(ik, qpos, window, repair, finisher)
        if judge.keeps(candidate, repair):
            return candidate
    return None


def raised_frames(ik: RetargetIk, qpos: np.ndarray, repair: PelvisRepair) -> np.ndarray:
    """(T,) the scaled human hips are under `hips_below_m` and the pelvis is more than
    `raised_m` above its target."""
    near_floor = ik.targets.human_pelvis[:, 2] < repair.hips_below_m
    return near_floor & (pelvis_excess(ik, qpos) > repair.raised_m)


def visibly_raised(ik: RetargetIk, qpos: np.ndarray, repair: PelvisRepair) -> np.ndarray:
    """(T,) the pelvis is more than `visible_m` higher over the scaled human hips than its median
    over the clip: the deviation the quality ruler reads."""
    deviation = pelvis_height_deviation(pelvis_heights(ik, qpos), ik.targets.human_pelvis[:, 2])
    return deviation > repair.visible_m


def pelvis_excess(ik: RetargetIk, qpos: np.ndarray) -> np.ndarray:
    """(T,) how far (m) the pelvis of each row of `qpos` is above its target."""
    root = ik.targets.bodies.index(ik.robot.config.root_body)
    return pelvis_heights(ik, qpos) - ik.targets.positions[:, root, 2]


def pelvis_heights(ik: RetargetIk, qpos: np.ndarray) -> np.ndarray:
    """(T,) the height (m) of the pelvis in each row of `qpos`."""
    body = ik.robot.body_ids[ik.robot.config.root_body]
    heights = np.empty(len(qpos))
    for t, q in enumerate(qpos):
        ik.configuration.update(q)
        heights[t] = ik.configuration.data.xpos[body, 2]
    return heights


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


def _solve_lower(ik: RetargetIk, qpos: np.ndarray, window: RepairWindow, lag_limit: float, gain: float) -> np.ndarray:
    """Frames after `anchor` up to `rejoin_end` solved forward again with the pelvis's position
    costs times `gain`, then cross-faded into `qpos` after `backward_start`."""
    root = ik.targets.bodies.index(ik.robot.config.root_body)
    first_costs = ik.position_costs
    # A new array, not an edit in place: the IK compares each frame's costs with those it applied.
    ik.position_costs = first_costs.copy()
    ik.position_costs[window.anchor + 1 : window.rejoin_end + 1, root] *= gain
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


@dataclass(frozen=True)
class _WindowJudge:
    """A window's first solve, finished over the window and `judge_margin_s` around it (an IK over
    those frames alone), against which each re-solve of the window is judged finished the same way."""

    part: RetargetIk
    """An IK over the window and its margin alone."""
    finish: Callable[[np.ndarray], np.ndarray]
    """The passes after the IK over the window and its margin."""
    first: np.ndarray
    """The first solve over the window and its margin."""
    window_rows: slice
    """The window's rows within `first`."""
    pelvis_m: float
    """The first solve's finished mean pelvis excess over its target."""
    skate_m_s: float
    """The first solve's finished `floor_skate`."""

    @classmethod
    def of(
        cls, ik: RetargetIk, qpos: np.ndarray, window: RepairWindow, repair: PelvisRepair, finisher: Finisher
    ) -> _WindowJudge:
        margin = int(round(repair.judge_margin_s * ik.targets.fps))
        frames = slice(max(window.anchor + 1 - margin, 0), min(window.rejoin_end + 1 + margin, len(qpos)))
        part, finish = finisher(frames)
        first = qpos[frames]
        finished = finish(first)
        return cls(
            part=part,
            finish=finish,
            first=first,
            window_rows=slice(window.anchor + 1 - frames.start, window.rejoin_end + 1 - frames.start),
            pelvis_m=_mean_excess(part, finished),
            skate_m_s=floor_skate(part, finished),
        )

    def keeps(self, candidate: np.ndarray, repair: PelvisRepair) -> bool:
        """Finished, the candidate's pelvis is lower on the mean and its feet slide at most
        `skate_tolerance_m_s` faster than the first solve's."""
        rows = self.first.copy()
        rows[self.window_rows] = candidate
        finished = self.finish(rows)
        lower = _mean_excess(self.part, finished) < self.pelvis_m
        slide = floor_skate(self.part, finished) - self.skate_m_s
        return bool(lower and slide <= repair.skate_tolerance_m_s)


def _mean_excess(ik: RetargetIk, qpos: np.ndarray) -> float:
    """Mean height (m) of the pelvis above its target over the rows where it is above it, zero elsewhere."""
    return float(np.maximum(pelvis_excess(ik, qpos), 0.0).mean())
