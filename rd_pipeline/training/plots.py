"""PNG plots of a training (matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.ticker import MaxNLocator

from rd_pipeline.env.mdp.rewards import GROUPS


def plot_learning_curve(rows: list[dict], best: dict, path: Path, title: str = "") -> None:
    """Reward per group and episode length per iteration, and each checkpoint's start-zero survival
    with `best` (the log row of the best-scored checkpoint) marked."""
    it = [r["iteration"] for r in rows]
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.6))
    for g in GROUPS:
        axes[0].plot(it, [r[f"reward_{g}"] for r in rows], label=g, lw=1)
    axes[0].set_xlabel("iteration")
    axes[0].set_ylabel("mean reward per step")
    axes[0].legend(fontsize=7)
    axes[1].plot(it, [r["episode_length_s"] or 0 for r in rows], lw=1)
    axes[1].set_xlabel("iteration")
    axes[1].set_ylabel("mean episode length (s)")
    scored = [r for r in rows if "start_zero_s" in r]
    axes[2].plot([r["iteration"] for r in scored], [r["start_zero_s"] for r in scored], "o-", lw=1, ms=3)
    axes[2].plot([best["iteration"]], [best["start_zero_s"]], "r*", ms=12, label=f"best scored: {best['iteration']}")
    axes[2].legend(fontsize=7)
    axes[2].set_xlabel("checkpoint iteration")
    # Scored by train on the training model under randomized physics of its own seed.
    axes[2].set_ylabel("start-zero survival,\ntraining model, randomized (s)")
    for axis in axes:
        axis.xaxis.set_major_locator(MaxNLocator(integer=True))
    fig.suptitle(title or "training", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
