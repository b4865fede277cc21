"""Benchmark: the CVXPY prior solve at 500 segments x 4 joints x 20 bins, and a failure-aware sampling profile.

    python -m bench.sampling [--repeats 7] [--out bench/results/sampling.json]

The issue's bar: the 500 x 4 x 20 solve in under 1 s (construction + solve, median). The profile
plot feeds the sampler a synthetic failure pattern (segments fail with a probability that rises
with their knee-pitch spread) for 20K steps and draws EMA failure rate and sampling probability.
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

import numpy as np
import torch

from rd_pipeline.sampling.plots import plot_sampler_profile
from rd_pipeline.sampling.prior import solve_balanced_prior
from rd_pipeline.sampling.sampler import SamplerConfig, SegmentSampler


def synthetic_histograms(rng: np.random.Generator, segments: int, joints: int, bins: int) -> np.ndarray:
    """Dance-like occupancy: each segment visits a few neighbouring bins around a common mode."""
    histograms = np.zeros((segments, joints, bins))
    for s in range(segments):
        for k in range(joints):
            centre = int(np.clip(rng.normal(bins * 0.4, bins * 0.15), 0, bins - 1))
            width = rng.integers(1, 4)
            lo, hi = max(0, centre - width), min(bins, centre + width + 1)
            histograms[s, k, lo:hi] = rng.random(hi - lo) + 0.1
            histograms[s, k] /= histograms[s, k].sum()
    return histograms


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--out", type=Path, default=Path("bench/results/sampling.json"))
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    histograms = synthetic_histograms(rng, 500, 4, 20)
    lengths = np.full(500, 50)
    times = [solve_balanced_prior(histograms, lengths, "CLARABEL").solve_s for _ in range(args.repeats)]
    prior = solve_balanced_prior(histograms, lengths, "CLARABEL")

    spread = histograms[:, 1].std(axis=1)
    fail_probability = np.clip((spread - spread.min()) / np.ptp(spread), 0.02, 0.9)
    sampler = SegmentSampler(SamplerConfig(), torch.as_tensor(prior.weights), seed=0)
    for _ in range(200):  # 200 updates x 100 steps = 20K steps, 64 episode ends per update
        segments = sampler.sample(64)
        failed = (
            torch.rand(64, generator=sampler.generator, dtype=torch.float64)
            < torch.as_tensor(fail_probability)[segments]
        )
        sampler.record(segments, segments, failed)
        sampler.advance(100)
    probability = sampler.probabilities().numpy()
    plot = args.out.with_name("sampler_profile.png")
    plot_sampler_profile(sampler.failure_rate.numpy(), probability, 1 / 500, plot)
    result = {
        "problem": "500 segments x 4 joints x 20 bins",
        "solver": "CLARABEL",
        "solve_median_s": round(statistics.median(times), 4),
        "solve_target_s": 1.0,
        "segments_with_weight": int((prior.weights > 1e-6).sum()),
        "profile_plot": str(plot),
        "max_probability_over_uniform": round(float(probability.max() * 500), 3),
        "correlation_failure_rate_vs_probability": round(
            float(np.corrcoef(sampler.failure_rate.numpy(), probability)[0, 1]), 3
        ),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
