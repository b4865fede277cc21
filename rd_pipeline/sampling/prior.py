"""The distribution-balanced prior: w* = argmin ||H w - U||^2 over the probability simplex (CVXPY)."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from rd_pipeline.errors import PipelineError

PRIOR_FILE = "prior.npz"
"""File name of the balanced prior inside a `prior` artifact."""


@dataclass(frozen=True)
class BalancedPrior:
    """Segment weights that flatten the sampled joint marginals, and how much flatter they are."""

    weights: np.ndarray
    """(S,) w*, on the simplex."""
    time_weights: np.ndarray
    """(S,) uniform-time weights (proportional to segment length): the 'before'."""
    marginal_before: np.ndarray
    """(K, B) marginal of each selected joint under uniform-time sampling."""
    marginal_after: np.ndarray
    """(K, B) marginal under w*."""
    solve_s: float
    """Wall time of the CVXPY solve (problem construction included)."""
    solver: str
    """The solver CVXPY was told to use."""


def solve_balanced_prior(histograms: np.ndarray, lengths: np.ndarray, solver: str) -> BalancedPrior:
    """Fit the stacked per-segment histograms (S, K, B) to a uniform target on the simplex."""
    # Imported here: training loads a prior without solving one, and needs no cvxpy.
    import cvxpy as cp

    n_segments, n_joints, n_bins = histograms.shape
    H = histograms.reshape(n_segments, -1).T  # (K*B, S): column s is segment s
    U = np.full(n_joints * n_bins, 1.0 / n_bins)
    began = time.perf_counter()
    w = cp.Variable(n_segments)
    problem = cp.Problem(cp.Minimize(cp.sum_squares(H @ w - U)), [w >= 0, cp.sum(w) == 1])
    try:
        problem.solve(solver=solver)
    except cp.error.SolverError as exc:
        raise PipelineError(f"prior.solver '{solver}' failed: {exc}") from None
    solve_s = time.perf_counter() - began
    if w.value is None or problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
        raise PipelineError(f"prior: solver {solver} returned status '{problem.status}'")
    # Solver tolerances leave tiny negatives; project back onto the simplex exactly.
    weights = np.maximum(w.value, 0.0)
    weights /= weights.sum()
    time_weights = lengths / lengths.sum()
    return BalancedPrior(
        weights=weights,
        time_weights=time_weights,
        marginal_before=np.einsum("s,skb->kb", time_weights, histograms),
        marginal_after=np.einsum("s,skb->kb", weights, histograms),
        solve_s=solve_s,
        solver=solver,
    )


def flatness(marginal: np.ndarray, support: np.ndarray) -> dict[str, np.ndarray]:
    """Distance of each joint's marginal (K, B) from uniform over the bins the motion visits (K, B bool).

    Bins no segment ever reaches cannot be filled by any weighting, so uniform is taken over the
    support: total variation (0 = flat) and KL(marginal || uniform) in nats.
    """
    tv = []
    kl = []
    for row, mask in zip(marginal, support):
        p = row[mask] / row[mask].sum()
        u = 1.0 / mask.sum()
        tv.append(0.5 * np.abs(p - u).sum())
        nonzero = p > 0
        kl.append(float(np.sum(p[nonzero] * np.log(p[nonzero] / u))))
    return {"total_variation": np.array(tv), "kl_nats": np.array(kl)}
