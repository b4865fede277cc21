"""`prior`: segment histograms -> the CVXPY balanced prior w* on the simplex, with a before/after plot."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rd_pipeline.artifacts.stage import Stage, StageContext

PLOT_FILE = "balancing.png"
SOLVER_ZERO = 1e-6
"""Weights up to this are an interior-point solver's zeros, not segments the prior samples."""


@dataclass(frozen=True)
class PriorConfig:
    """The solve."""

    solver: str = "CLARABEL"
    """CVXPY solver, named explicitly so results do not depend on what happens to be installed."""


def _run(ctx: StageContext) -> dict[str, Any]:
    import numpy as np

    from rd_pipeline.sampling.plots import plot_balancing
    from rd_pipeline.sampling.prior import PRIOR_FILE, flatness, solve_balanced_prior
    from rd_pipeline.sampling.segments import SEGMENTS_FILE, SegmentStats

    stats = SegmentStats.load(ctx.upstream["segment_stats"].path / SEGMENTS_FILE)
    prior = solve_balanced_prior(stats.histograms, stats.lengths, ctx.params.solver)
    np.savez(
        ctx.out_dir / PRIOR_FILE,
        weights=prior.weights,
        time_weights=prior.time_weights,
        marginal_before=prior.marginal_before,
        marginal_after=prior.marginal_after,
        starts=stats.starts,
        lengths=stats.lengths,
        fps=stats.fps,
    )
    plot_balancing(stats, prior, ctx.out_dir / PLOT_FILE)
    support = stats.histograms.sum(axis=0) > 0
    before = flatness(prior.marginal_before, support)
    after = flatness(prior.marginal_after, support)
    per_joint = lambda values: {j: round(float(v), 4) for j, v in zip(stats.selected, values)}
    return {
        "segments": stats.n_segments,
        "solver": prior.solver,
        "solve_s": round(prior.solve_s, 4),
        "tv_before": per_joint(before["total_variation"]),
        "tv_after": per_joint(after["total_variation"]),
        "kl_before_nats": per_joint(before["kl_nats"]),
        "kl_after_nats": per_joint(after["kl_nats"]),
        "weight_max_over_uniform": round(float(prior.weights.max() * stats.n_segments), 3),
        "segments_with_weight": int((prior.weights > SOLVER_ZERO).sum()),
    }


STAGE = Stage(
    name="prior",
    version=1,
    description="segment histograms -> balanced prior w* (CVXPY, simplex) + before/after plot",
    params=PriorConfig,
    provides="sampling_prior",
    run=_run,
    requires=("segment_stats",),
    headline=("segments_with_weight", "weight_max_over_uniform"),
)
