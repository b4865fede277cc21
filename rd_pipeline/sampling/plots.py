"""PNG plots of the sampling statistics (matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from rd_pipeline.sampling.prior import BalancedPrior
from rd_pipeline.sampling.segments import SegmentStats


def plot_segment_statistics(stats: SegmentStats, joint_pos: np.ndarray, joints: tuple[str, ...], path: Path) -> None:
    """Lower-body joints per segment: mean and min-max band (the paper's "Lower-Body Joint Statistics")."""
    columns = [stats.joint_names.index(j) for j in joints]
    time_s = (stats.starts + stats.lengths / 2) / stats.fps
    fig, axes = plt.subplots(len(joints), 1, figsize=(10, 1.6 * len(joints)), sharex=True, squeeze=False)
    for ax, joint, column in zip(axes[:, 0], joints, columns):
        windows = [joint_pos[s : s + n, column] for s, n in zip(stats.starts, stats.lengths)]
        mean = np.array([w.mean() for w in windows])
        ax.fill_between(time_s, [w.min() for w in windows], [w.max() for w in windows], alpha=0.3, step="mid")
        ax.plot(time_s, mean, lw=1)
        ax.set_ylabel(joint.replace("_joint", ""), fontsize=7, rotation=0, ha="right")
        ax.tick_params(labelsize=7)
    axes[-1, 0].set_xlabel("time (s), one point per 1 s segment")
    fig.suptitle("Lower-body joint statistics per segment (mean, min-max)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_balancing(stats: SegmentStats, prior: BalancedPrior, path: Path) -> None:
    """Marginal of each selected joint before (uniform time) and after (w*) balancing, overlaid."""
    fig, axes = plt.subplots(1, len(stats.selected), figsize=(3.2 * len(stats.selected), 2.8), squeeze=False)
    for k, (ax, joint) in enumerate(zip(axes[0], stats.selected)):
        edges = stats.bin_edges[k]
        width = np.diff(edges)
        marginals = (
            (prior.marginal_before[k], "tab:blue", "before balancing"),
            (prior.marginal_after[k], "tab:red", "after balancing"),
        )
        for marginal, color, label in marginals:
            ax.bar(edges[:-1], marginal, width=width, align="edge", color=color, alpha=0.5, label=label)
        ax.set_title(joint.replace("_joint", ""), fontsize=8)
        ax.set_xlabel("rad", fontsize=7)
        ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Distribution-aware balancing: sampled joint marginals")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_sampler_profile(
    failure_rate: np.ndarray, probability: np.ndarray, uniform: float, path: Path, title: str = ""
) -> None:
    """Failure-aware sampling profile: EMA failure rate and sampling probability per segment."""
    segments = np.arange(len(failure_rate))
    fig, ax = plt.subplots(figsize=(10, 3.4))
    ax.bar(segments, failure_rate, color="tab:orange", alpha=0.6, label="EMA failure rate")
    ax.set_ylim(0, max(1e-3, float(failure_rate.max())) * 1.1)  # a rate is never negative
    ax.set_xlabel("segment (1 s)")
    ax.set_ylabel("failure rate")
    twin = ax.twinx()
    twin.plot(segments, probability, color="tab:blue", lw=1.2, label="sampling probability")
    twin.axhline(uniform, color="gray", ls="--", lw=0.8, label="uniform")
    twin.set_ylim(0, max(float(probability.max()), uniform) * 1.1)
    twin.set_ylabel("probability")
    ax.set_title(f"{title}\nfailure-aware sampling at the end of training" if title else "failure-aware sampling")
    # Below the axes, where it covers neither bars nor ticks.
    fig.legend(loc="lower center", ncol=3, fontsize=7)
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
