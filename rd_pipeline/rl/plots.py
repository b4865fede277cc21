"""PNG plots of a training (matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from rd_pipeline.rl.rewards import GROUPS


def plot_learning_curve(rows: list[dict], best: dict, path: Path) -> None:
    """Reward per group and episode length per iteration, and each checkpoint's start-zero survival
    with `best` (the log row of the checkpoint chosen) marked."""
    it = [r["iteration"] for r in rows]
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.2))
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
    axes[2].plot([best["iteration"]], [best["start_zero_s"]], "r*", ms=12, label=f"best: {best['iteration']}")
    axes[2].legend(fontsize=7)
    axes[2].set_xlabel("checkpoint iteration")
    axes[2].set_ylabel("start-zero survival, nominal (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
