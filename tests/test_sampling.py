"""Segment statistics, the CVXPY balanced prior and the bounded-mixture sampler, on real dances."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import RETARGETED_DIR, cli, h1_2_dance_env

from rd_pipeline.env.config import EnvConfig
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.robots import load_robot
from rd_pipeline.sampling.prior import flatness, solve_balanced_prior
from rd_pipeline.sampling.sampler import SamplerConfig, SegmentSampler, water_fill
from rd_pipeline.sampling.segments import SegmentStats, segment_bounds, segment_statistics

MASK = ("left_hip_pitch_joint", "left_knee_joint", "right_hip_pitch_joint", "right_knee_joint")


def _stats(robot_name: str, motion: str) -> SegmentStats:
    robot = load_robot(robot_name)
    reference = import_retargeted_csv(
        RETARGETED_DIR / robot_name / f"{motion}.csv", robot, 30.0, 50.0, "cubic", ContactThresholds()
    ).reference
    limits = robot.joint_range[[robot.config.joint_names.index(j) for j in MASK]]
    return segment_statistics(reference.joint_pos, reference.joint_names, 50.0, MASK, limits, 1.0, 0.25, 20)


@pytest.fixture(scope="module", params=[("g1", "dance1_subject2"), ("h1_2", "dance2_subject4")])
def stats(request) -> SegmentStats:
    return _stats(*request.param)


def test_segments_cover_every_frame() -> None:
    starts, lengths = segment_bounds(11285, 50.0, 1.0, 0.25)
    assert len(starts) == 226 and lengths[-1] == 35 and lengths.sum() == 11285
    # A 10-frame tail (0.2 s) is shorter than min_last_s: it joins the previous segment.
    starts, lengths = segment_bounds(6560, 50.0, 1.0, 0.25)
    assert len(starts) == 131 and lengths[-1] == 60 and lengths.sum() == 6560


def test_histograms_are_normalized(stats: SegmentStats) -> None:
    assert stats.histograms.shape == (stats.n_segments, 4, 20)
    assert np.allclose(stats.histograms.sum(axis=2), 1.0)
    # The segments tile the whole take: G1 dance1_subject2 (6575 frames at 50 Hz) or H1-2 dance2_subject4 (11285).
    assert stats.starts[0] == 0 and np.array_equal(stats.starts[1:], np.cumsum(stats.lengths)[:-1])
    assert stats.lengths.sum() in (6575, 11285)


def test_prior_is_on_the_simplex_and_flattens_every_joint(stats: SegmentStats) -> None:
    prior = solve_balanced_prior(stats.histograms, stats.lengths, "CLARABEL")
    assert prior.weights.shape == (stats.n_segments,)
    assert prior.weights.min() >= 0.0 and prior.weights.sum() == pytest.approx(1.0, abs=1e-9)
    support = stats.histograms.sum(axis=0) > 0
    before = flatness(prior.marginal_before, support)["total_variation"]
    after = flatness(prior.marginal_after, support)["total_variation"]
    # Measurably flatter on every selected joint: at least a third less total variation.
    assert np.all(after < 0.67 * before), (before, after)


def test_prior_is_deterministic(stats: SegmentStats) -> None:
    a = solve_balanced_prior(stats.histograms, stats.lengths, "CLARABEL").weights
    b = solve_balanced_prior(stats.histograms, stats.lengths, "CLARABEL").weights
    assert np.array_equal(a, b)


def test_water_fill_cap_holds_after_normalization() -> None:
    weights = torch.tensor([100.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], dtype=torch.float64)
    p = water_fill(weights, cap=0.4)
    assert p.sum().item() == pytest.approx(1.0) and p.max().item() == pytest.approx(0.4)
    # The excess goes to the others in proportion to their weight: zeros stay zero.
    assert torch.allclose(p[1:4], torch.full((3,), 0.2, dtype=torch.float64)) and p[4:].sum() == 0


def test_sampler_cap_with_a_concentrated_failure(stats: SegmentStats) -> None:
    prior = solve_balanced_prior(stats.histograms, stats.lengths, "CLARABEL")
    sampler = SegmentSampler(SamplerConfig(), torch.as_tensor(prior.weights), seed=0)
    for _ in range(40):  # one segment fails every time
        segments = torch.tensor([3, 3, 7])
        sampler.record(segments, segments, torch.tensor([True, True, False]))
        sampler.advance(100)
    p = sampler.probabilities()
    cap = 4.0 / stats.n_segments
    assert p.sum().item() == pytest.approx(1.0)
    assert p.max().item() <= cap * (1 + 1e-9) and p[3].item() == pytest.approx(cap)
    assert sampler.failure_rate[3].item() == pytest.approx(1 - 0.95**40) and sampler.failure_rate[7] == 0


def test_failure_credit_start_or_visited() -> None:
    """Two episodes on ten segments: one from segment 2 failing in segment 5, one from segment 0
    running to the end of the clip."""
    start = torch.tensor([2, 0])
    end = torch.tensor([5, 9])
    failed = torch.tensor([True, False])
    rates = {}
    for credit in ("start", "visited"):
        sampler = SegmentSampler(SamplerConfig(failure_credit=credit), torch.ones(10), seed=0)
        sampler.record(start, end, failed)
        if credit == "visited":
            assert sampler.attempts.tolist() == [1, 1, 2, 2, 2, 2, 1, 1, 1, 1]
        sampler.advance(100)
        rates[credit] = sampler.failure_rate.tolist()
    # `start`: the whole failure is held against the segment the episode began in.
    assert rates["start"] == pytest.approx([0, 0, 0.05, 0, 0, 0, 0, 0, 0, 0])
    # `visited`: against segment 5, which two episodes reached and one failed in.
    assert rates["visited"] == pytest.approx([0, 0, 0, 0, 0, 0.025, 0, 0, 0, 0])


def test_visited_credit_in_the_environment_follows_where_episodes_end() -> None:
    """Zero actions on H1-2 dance2_subject4: the robot falls within about a second, from starts all
    over the take. The sampler's counts equal those rebuilt from the environment's own frames: one
    visit per segment from the start frame to the frame where the episode ended, the failure
    against the last."""
    credit = SamplerConfig(failure_credit="visited", update_interval=10**9)
    env = h1_2_dance_env(EnvConfig(num_envs=16), sampler_config=credit)
    segment_of = lambda frames: torch.searchsorted(env.command.segment_starts, frames, right=True) - 1
    visits = torch.zeros(env.sampler.n_segments, dtype=torch.float64)
    failures = torch.zeros(env.sampler.n_segments, dtype=torch.float64)
    spans = []
    for _ in range(120):
        first = segment_of(env.command.start_frame.clone())
        last = segment_of(env.command.next_frame())
        _, _, dones, extras = env.step(torch.zeros(env.num_envs, env.num_actions))
        for i in torch.nonzero(dones).flatten().tolist():
            visits[first[i] : last[i] + 1] += 1
            failures[last[i]] += float(not extras["time_outs"][i])
            spans.append(int(last[i] - first[i]) + 1)
    assert len(spans) > 100 and failures.sum() > 100
    assert max(spans) >= 2  # some episodes crossed a segment boundary
    assert torch.equal(env.sampler.attempts, visits)
    assert torch.equal(env.sampler.failures, failures)


@pytest.mark.parametrize(
    ("step", "failure", "distribution"),
    [
        (0, 0.4, 0.2),
        (48_000, 0.4, 0.2),
        (72_000, 0.475, 0.125),
        (96_000, 0.55, 0.05),
        (200_000, 0.55, 0.05),
    ],
)
def test_mixture_ramps_hit_the_appendix_values(step: int, failure: float, distribution: float) -> None:
    sampler = SegmentSampler(SamplerConfig(), torch.ones(10), seed=0)
    uniform, d, f = sampler.mixture_weights(step)
    assert (uniform, d, f) == pytest.approx((0.3, distribution, failure))


def test_modes_for_the_ablation() -> None:
    balanced = torch.tensor([0.7, 0.1, 0.1, 0.1, 0.0], dtype=torch.float64)
    uniform = SegmentSampler(SamplerConfig(mode="uniform"), balanced, seed=0).probabilities()
    assert torch.allclose(uniform, torch.full((5,), 0.2, dtype=torch.float64))
    distribution = SegmentSampler(SamplerConfig(mode="distribution", cap_factor=10.0), balanced, seed=0).probabilities()
    assert distribution[0].item() == pytest.approx(0.3 * 0.2 + 0.7 * 0.7)
    with pytest.raises(ValueError, match="sampler mode must be one of"):
        SegmentSampler(SamplerConfig(mode="greedy"), balanced, seed=0)


def test_same_seed_same_samples_and_state_round_trip() -> None:
    balanced = torch.rand(50, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    a, b = SegmentSampler(SamplerConfig(), balanced, seed=7), SegmentSampler(SamplerConfig(), balanced, seed=7)
    assert torch.equal(a.sample(4096), b.sample(4096))
    a.record(torch.tensor([1, 2]), torch.tensor([1, 4]), torch.tensor([True, False]))
    a.advance(250)
    state = a.state_dict()
    c = SegmentSampler(SamplerConfig(), balanced, seed=99)
    c.load_state_dict(state)
    assert torch.equal(a.sample(1000), c.sample(1000)) and c.step == 250
    assert not torch.equal(SegmentSampler(SamplerConfig(), balanced, seed=8).sample(4096), b.sample(4096))


@pytest.mark.slow
def test_stages_write_both_artifacts_with_plots(artifacts: Path) -> None:
    result = cli("run", "--robot", "h1_2", "--motion", "dance2_subject4", "--until", "prior")
    assert result.returncode == 0, result.stderr
    (stats_dir,) = (artifacts / "stats" / "h1_2" / "dance2_subject4").iterdir()
    (prior_dir,) = (artifacts / "prior" / "h1_2" / "dance2_subject4").iterdir()
    assert (stats_dir / "lower_body_segments.png").stat().st_size > 10_000
    assert (prior_dir / "balancing.png").stat().st_size > 10_000
    metrics = json.loads((prior_dir / "manifest.json").read_text())["metrics"]
    assert metrics["solver"] == "CLARABEL" and metrics["segments"] == 226
    assert all(metrics["tv_after"][j] < metrics["tv_before"][j] for j in MASK)
    summary = json.loads((stats_dir / "stats.json").read_text())
    assert summary["last_segment_frames"] == 35 and len(summary["std_ranking"]["ranked"]) == 21
