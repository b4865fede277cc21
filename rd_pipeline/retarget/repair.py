"""Lag repair: stretches the forward solve left far behind their targets, solved again from both ends."""

from __future__ import annotations

from dataclasses import dataclass

import mink
import numpy as np

from rd_pipeline.retarget.config import LagRepair
from rd_pipeline.retarget.ik import RetargetIk
from rd_pipeline.retarget.quality import colliding_frames
from rd_pipeline.retarget.smoothing import blend_configurations


@dataclass(frozen=True)
class RepairWindow:
    """One re-solved stretch of frames."""

    anchor: int
    """The last frame kept from the forward solve; the re-solve starts after it."""
    backward_start: int
    """The last frame of the padded lagging stretch, where the backward solve starts."""
    rejoin_end: int
    """The last frame the re-solve fades into the forward solve."""


def lagging_windows(errors: np.ndarray, fps: float, repair: LagRepair) -> list[RepairWindow]:
    """Padded stretches of frames whose keypoint error is far above the take's median."""
    if repair.error_ratio <= 0:
        return []
    median = float(np.median(errors))
    threshold = max(repair.error_ratio * median, median + repair.error_margin_m)
    return padded_windows(errors > threshold, fps, repair.padding_s, repair.rejoin_s)


def padded_windows(frames: np.ndarray, fps: float, padding_s: float, rejoin_s: float) -> list[RepairWindow]:
    """The stretches of the (T,) bool `frames`, padded by `padding_s` on both sides (overlapping
    ones merged), each rejoining the first solve over `rejoin_s`."""
    padding = int(round(padding_s * fps))
    rejoin = int(round(rejoin_s * fps))
    last_frame = len(frames) - 1
    spans: list[list[int]] = []
    for t in np.flatnonzero(frames):
        start = max(int(t) - padding, 0)
        end = min(int(t) + padding, last_frame)
        if spans and start <= spans[-1][1]:
            spans[-1][1] = end
        else:
            spans.append([start, end])
    windows = []
    for start, end in spans:
        if end > start:
            windows.append(RepairWindow(start, end, min(end + rejoin, last_frame)))
    return windows


def repair_lag(ik: RetargetIk, qpos: np.ndarray, repair: LagRepair) -> tuple[np.ndarray, int]:
    """`qpos` with its lagging stretches re-solved where that lowers their error and brings no
    configured body pair into contact, or deeper into it, than it was (`brings_contact`), and how
    many were.

    The re-solve keeps its pairs apart, but its fade back into the forward solve blends two
    configurations: on G1 ground2_subject3 that swung an elbow 8 cm into the torso."""
    errors = ik.keypoint_errors(qpos)
    lag_limit = float(np.median(errors)) + ik.settings.catch_up_margin_m
    out = qpos.copy()
    repaired = 0
    for window in lagging_windows(errors, ik.targets.fps, repair):
        guide = _guide(ik, out, errors, window, lag_limit, repair)
        candidate, candidate_errors = _best_re_solve(ik, out, guide, window, lag_limit, repair)
        span = slice(window.anchor + 1, window.rejoin_end + 1)
        lowers_peak = candidate_errors.max() < errors[span].max()
        lowers_mean = candidate_errors.mean() <= errors[span].mean()
        if lowers_peak and lowers_mean and not brings_contact(ik, candidate, out[span]):
            out[span] = candidate
            errors[span] = candidate_errors
            repaired += 1
    return out, repaired


def _best_re_solve(
    ik: RetargetIk, qpos: np.ndarray, guide: np.ndarray, window: RepairWindow, lag_limit: float, repair: LagRepair
) -> tuple[np.ndarray, np.ndarray]:
    """The window re-solved towards `guide` at each of `repair.guide_costs`, the one with the lowest
    mean keypoint error over the window (the first on a tie), and its per-frame errors."""
    candidates = [_solve_window_again(ik, qpos, guide, window, lag_limit, cost, repair) for cost in repair.guide_costs]
    errors = [ik.keypoint_errors(c, window.anchor + 1) for c in candidates]
    best = int(np.argmin([e.mean() for e in errors]))
    return candidates[best], errors[best]


def brings_contact(ik: RetargetIk, candidate: np.ndarray, first: np.ndarray) -> bool:
    """Whether `candidate` puts a configured body pair into contact where `first` had none, or
    deeper than the IK's step check allows where `first` only touched.

    On H1-2 ground2_subject3 the forward solve rested a wrist 2 mm into the torso and a re-solve
    pressed it 12 mm in; a check for new contact alone let that through."""
    for depth in (0.0, ik.settings.pair_depth_limit_m):
        if np.any(colliding_frames(ik.robot, candidate, depth) & ~colliding_frames(ik.robot, first, depth)):
            return True
    return False


def _guide(
    ik: RetargetIk,
    qpos: np.ndarray,
    errors: np.ndarray,
    window: RepairWindow,
    lag_limit: float,
    repair: LagRepair,
) -> np.ndarray:
    """Frames after `anchor` up to `rejoin_end`: per frame the better of the forward solve and a
    backward solve from `backward_start`, the forward solve after it."""
    first = window.anchor
    end = window.backward_start
    last = window.rejoin_end
    backward = _solve_backward(ik, qpos[end], range(end - 1, first, -1), lag_limit, repair.catch_up_min_gain_m)
    backward_errors = ik.keypoint_errors(backward, first + 1)
    guide = qpos[first + 1 : last + 1].copy()
    better = backward_errors < errors[first + 1 : end]
    n_backward = end - first - 1
    guide[:n_backward] = np.where(better[:, None], backward, guide[:n_backward])
    return guide


def _solve_window_again(
    ik: RetargetIk,
    qpos: np.ndarray,
    guide: np.ndarray,
    window: RepairWindow,
    lag_limit: float,
    guide_cost: float,
    repair: LagRepair,
) -> np.ndarray:
    """Frames after `anchor` up to `rejoin_end` solved forward again, pulled towards `guide` at
    `guide_cost`, then cross-faded into the forward solve after `backward_start`."""
    first = window.anchor
    last = window.rejoin_end
    guide_task = mink.PostureTask(ik.robot.model, cost=guide_cost)
    resolved = np.empty_like(guide)
    previous = qpos[first]
    ik.configuration.update(previous)
    for k, t in enumerate(range(first + 1, last + 1)):
        guide_task.set_target(guide[k])
        resolved[k] = ik.solve_frame(
            t,
            previous,
            ik.root_steps[t],
            lag_limit,
            (guide_task,),
            repair.catch_up_min_gain_m,
        )
        previous = resolved[k]
    return fade_into(qpos, resolved, window)


def fade_into(qpos: np.ndarray, resolved: np.ndarray, window: RepairWindow) -> np.ndarray:
    """`resolved` (the frames after `anchor` up to `rejoin_end`) cross-faded into `qpos` over the
    frames after `backward_start`."""
    first = window.anchor
    end = window.backward_start
    last = window.rejoin_end
    fade = np.ones(len(resolved))
    tail = last - end
    if tail > 0:
        fade[end - first :] = np.arange(tail, 0, -1) / (tail + 1)
    return blend_configurations(qpos[first + 1 : last + 1], resolved, fade)


def _solve_backward(
    ik: RetargetIk,
    start: np.ndarray,
    frames: range,
    lag_limit: float,
    catch_up_min_gain_m: float,
) -> np.ndarray:
    """Frames in reverse order from `start`, returned in forward order (one row per frame)."""
    out = np.empty((len(frames), len(start)))
    previous = start
    ik.configuration.update(start)
    for k, t in enumerate(frames):
        # Going back in time, frame t is reached from t + 1: that step's root budget applies.
        out[k] = ik.solve_frame(t, previous, ik.root_steps[t + 1], lag_limit, (), catch_up_min_gain_m)
        previous = out[k]
    return out[::-1]
