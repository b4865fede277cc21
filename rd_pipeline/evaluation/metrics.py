"""Validation metrics (SPEC "Metrics"): protocol summaries, error means, drift with bootstrap CI,
and the reduction of several seeds to a mean with a 95% Student-t interval."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from rd_pipeline.evaluation.protocol import TrackingTolerance
    from rd_pipeline.evaluation.sim2sim import Rollout

ERROR_METRICS = ("E_g_mpbpe", "E_mpbpe", "E_mpjpe", "E_mpjve", "E_mpbve")
SUCCESS_THRESHOLDS_S = (10, 20, 30)
DRIFT_BINS = 6


def summarize(rollouts: list[Rollout], control_hz: float) -> dict[str, float | None]:
    """Fixed-grid summary: completion %, mean survival (s) and the most it could be (every start
    lasting to the clip's end), success at 10/20/30 s, error means.

    Success at T counts the rollouts that survived T seconds among those whose start left at least
    T seconds of reference (None when no start did). Errors are means over every step survived.
    """
    survival = np.array([r.steps for r in rollouts]) / control_hz
    out: dict[str, float | None] = {
        "rollouts": len(rollouts),
        "completion_pct": round(100.0 * float(np.mean([r.completed for r in rollouts])), 2),
        "mean_survival_s": round(float(survival.mean()), 3),
        # A start late in the clip can last only what is left of it: a 3.3 s mean looks poor until
        # one sees that 5.5 s is the most the grid allows.
        "mean_survival_ceiling_s": round(float(np.mean([r.remaining_steps for r in rollouts])) / control_hz, 3),
    }
    for threshold in SUCCESS_THRESHOLDS_S:
        eligible = [r for r in rollouts if r.remaining_steps >= threshold * control_hz]
        out[f"success_{threshold}s_pct"] = (
            round(100.0 * float(np.mean([r.steps >= threshold * control_hz for r in eligible])), 2)
            if eligible
            else None
        )
    for name in ERROR_METRICS:
        values = np.concatenate([r.errors[name] for r in rollouts])
        out[name] = round(float(values.mean()), 2) if len(values) else None
    return out


def drift(rollouts: list[Rollout], rng: np.random.Generator, resamples: int) -> list[dict[str, float | None]]:
    """E_g_mpbpe in `DRIFT_BINS` relative time bins of each rollout, with a bootstrap 95% CI.

    Each rollout contributes its mean error per bin; the CI resamples rollouts (or, with a single
    rollout, its steps within the bin)."""
    per_rollout = [np.array_split(r.errors["E_g_mpbpe"], DRIFT_BINS) for r in rollouts if r.steps >= DRIFT_BINS]
    out: list[dict[str, float | None]] = []
    for b in range(DRIFT_BINS):
        samples = [chunk[b] for chunk in per_rollout]
        if not samples:
            out.append({"bin": b, "mean": None, "ci_low": None, "ci_high": None})
            continue
        units = np.array([s.mean() for s in samples]) if len(samples) > 1 else samples[0]
        low, high = bootstrap_ci(units, rng, resamples)
        out.append(
            {"bin": b, "mean": round(float(units.mean()), 2), "ci_low": round(low, 2), "ci_high": round(high, 2)}
        )
    return out


def bootstrap_ci(values: np.ndarray, rng: np.random.Generator, resamples: int) -> tuple[float, float]:
    """Percentile 95% interval of the mean."""
    if len(values) == 1:
        return float(values[0]), float(values[0])
    means = rng.choice(values, size=(resamples, len(values)), replace=True).mean(axis=1)
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def t_interval(values: Sequence[float | None]) -> dict[str, float | int | None]:
    """Mean and 95% Student-t half-width over seeds (half-width None for a single seed)."""
    array = np.asarray([v for v in values if v is not None], dtype=float)
    if len(array) == 0:
        return {"mean": None, "ci95": None, "n": 0}
    if len(array) == 1:
        return {"mean": round(float(array[0]), 3), "ci95": None, "n": 1}
    from scipy import stats  # it probes torch on import; the CLI loads it only to reduce seeds

    half = stats.t.ppf(0.975, len(array) - 1) * array.std(ddof=1) / np.sqrt(len(array))
    return {"mean": round(float(array.mean()), 3), "ci95": round(float(half), 3), "n": len(array)}


def difference_interval(first: list[float], second: list[float]) -> dict[str, float | None]:
    """Mean of `first` minus mean of `second`, with Welch's 95% interval (None below two seeds a side)."""
    a = np.asarray(first, dtype=float)
    b = np.asarray(second, dtype=float)
    difference = float(a.mean() - b.mean())
    if len(a) < 2 or len(b) < 2:
        return {"difference": round(difference, 3), "low": None, "high": None}
    if a.std() == 0 and b.std() == 0:
        # No spread on either side: the interval is the difference itself (Welch's is undefined).
        return {"difference": round(difference, 3), "low": round(difference, 3), "high": round(difference, 3)}
    from scipy import stats

    interval = stats.ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
    return {
        "difference": round(difference, 3),
        "low": round(float(interval.low), 3),
        "high": round(float(interval.high), 3),
    }


def tracked_steps(rollout: Rollout, tolerance: TrackingTolerance) -> np.ndarray:
    """(steps,) whether each step survived was tracked: mean joint error and mean pelvis-relative
    body error both within `tolerance`."""
    joints = rollout.errors["E_mpjpe"] / 1000.0 <= tolerance.joint_rad
    bodies = rollout.errors["E_mpbpe"] / 1000.0 <= tolerance.body_m
    return joints & bodies


def tracked_pct(rollouts: list[Rollout], tolerance: TrackingTolerance) -> float:
    """Share of the steps the rollouts could have lasted (each to the clip's end) that were tracked (%)."""
    tracked = sum(int(tracked_steps(r, tolerance).sum()) for r in rollouts)
    most = sum(r.remaining_steps for r in rollouts)
    return round(100.0 * tracked / max(most, 1), 2)


def per_second(rollout: Rollout, control_hz: float, tolerance: TrackingTolerance) -> list[dict[str, float | None]]:
    """Per second of the clip from the rollout's start: mean joint error (rad), mean pelvis-relative
    body error (m) and the share of the second tracked (%); errors None once the rollout has ended."""
    step = int(round(control_hz))
    tracked = tracked_steps(rollout, tolerance)
    out: list[dict[str, float | None]] = []
    for first in range(0, rollout.remaining_steps, step):
        joints = rollout.errors["E_mpjpe"][first : first + step]
        bodies = rollout.errors["E_mpbpe"][first : first + step]
        steps = min(step, rollout.remaining_steps - first)
        out.append(
            {
                "second": first // step,
                "joint_rad": round(float(joints.mean()) / 1000.0, 4) if len(joints) else None,
                "body_m": round(float(bodies.mean()) / 1000.0, 4) if len(bodies) else None,
                "tracked_pct": round(100.0 * float(tracked[first : first + step].sum()) / steps, 1),
            }
        )
    return out
