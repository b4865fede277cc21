"""Study: where a floor cut's foot skate sits between plants, as a picture.

    python -m studies.swing_edges [--robot h1] [--take fallAndGetUp1_subject1]
                                  [--clip "fallAndGetUp1_subject1 138-158 s"] [--seconds 3]
                                  [--out docs/images/floor_skate_swing_edges_h1.png]

Retargets one floor cut (default params) and plots, for the foot and the window of `--seconds`
that carry most of the skate the ruler counts outside the targets' plants: the robot's sole
height beside the target's lift, both feet's horizontal speeds, and how far the robot's foot is
from its target.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from bench.retarget import retarget_and_score
from bench.retarget_variants import floor_cut
from rd_pipeline.errors import PipelineError
from rd_pipeline.retarget.quality import QualityThresholds, sole_heights_and_speeds
from rd_pipeline.robots import load_robot


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="h1")
    parser.add_argument("--take", default="fallAndGetUp1_subject1")
    parser.add_argument("--clip", default="fallAndGetUp1_subject1 138-158 s")
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--out", type=Path, default=Path("docs/images/floor_skate_swing_edges_h1.png"))
    args = parser.parse_args()
    try:
        robot = load_robot(args.robot)
        clip = floor_cut(args.take, args.clip)
    except PipelineError as exc:
        raise SystemExit(f"swing_edges: {exc}") from None
    result, quality, _ = retarget_and_score(clip, robot)
    reference = result.reference
    targets = result.targets
    soles, speed = sole_heights_and_speeds(robot, reference)
    planted = targets.foot_contact.astype(bool)
    between = (soles < QualityThresholds().ground_contact_height_m) & ~planted
    counted = np.where(between, speed, 0.0)
    side = int(np.argmax(counted.sum(axis=0)))
    width = int(args.seconds * reference.fps)
    start = int(np.argmax(np.convolve(counted[:, side], np.ones(width), "valid")))
    window = slice(start, start + width)
    foot = robot.config.foot_bodies[side]
    robot_xy = reference.body_pos_w[:, reference.body_names.index(foot), :2]
    target_xy = targets.positions[:, targets.bodies.index(foot), :2]
    series = {
        "sole": soles[window, side] * 100,
        "lift": targets.foot_lift[window, side] * 100,
        "robot_speed": _speed(robot_xy, reference.fps)[window] * 1000,
        "target_speed": _speed(target_xy, reference.fps)[window] * 1000,
        "gap": np.linalg.norm(robot_xy - target_xy, axis=1)[window] * 1000,
    }
    seconds = np.arange(start, start + width) / reference.fps
    title = f"{args.robot} {args.clip}, {foot}: skate {quality['skate_stance_mean_mm_s']:.1f} mm/s"
    _plot(seconds, series, planted[window, side], between[window, side], title, args.out)


def _speed(xy: np.ndarray, fps: float) -> np.ndarray:
    return np.r_[0.0, np.linalg.norm(np.diff(xy, axis=0), axis=1) * fps]


def _plot(
    seconds: np.ndarray,
    series: dict[str, np.ndarray],
    planted: np.ndarray,
    between: np.ndarray,
    title: str,
    out: Path,
) -> None:
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    axes[0].plot(seconds, series["sole"], label="robot sole height (cm)")
    axes[0].plot(seconds, series["lift"], label="target lift (cm)")
    axes[0].axhline(2.0, color="k", lw=0.5, ls="--", label="the skate ruler's 2 cm band")
    axes[0].fill_between(seconds, 0, 1, where=planted, transform=axes[0].get_xaxis_transform(), color="g", alpha=0.1)
    axes[0].set_ylim(0, 8)
    axes[1].plot(seconds, series["robot_speed"], label="robot foot, horizontal speed (mm/s)")
    axes[1].plot(seconds, series["target_speed"], label="target, horizontal speed (mm/s)")
    axes[1].fill_between(
        seconds,
        0,
        1,
        where=between,
        transform=axes[1].get_xaxis_transform(),
        color="r",
        alpha=0.2,
        label="counted, not planted",
    )
    axes[2].plot(seconds, series["gap"], label="robot foot to its target, horizontal (mm)")
    axes[2].set_xlabel("seconds into the cut (green: planted by the targets)")
    for axis in axes:
        axis.legend(fontsize=7, loc="upper left")
    fig.suptitle(title)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)


if __name__ == "__main__":
    main()
