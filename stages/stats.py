"""`stats`: reference motion -> 1 s segments, per-joint std, hip/knee-pitch occupancy histograms, plot."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from rd_pipeline.artifacts.stage import Stage, StageContext
from rd_pipeline.robots.assets import model_files

PLOT_FILE = "lower_body_segments.png"
SUMMARY_FILE = "stats.json"


@dataclass(frozen=True)
class StatsConfig:
    """Segmentation and histogram settings."""

    segment_s: float = 1.0
    """Segment length (s)."""
    min_last_s: float = 0.25
    """A last piece shorter than this joins the previous segment; a longer one is its own, shorter segment."""
    bins: int = 20
    """Histogram bins per joint, spanning the joint's limits."""


def _run(ctx: StageContext) -> dict[str, Any]:
    from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
    from rd_pipeline.robots import load_robot
    from rd_pipeline.robots.model import leg_joints
    from rd_pipeline.sampling.plots import plot_segment_statistics
    from rd_pipeline.sampling.segments import SEGMENTS_FILE, segment_statistics, std_ranking

    p: StatsConfig = ctx.params
    robot = load_robot(ctx.robot_name)
    config = robot.config
    reference = ReferenceMotion.load(ctx.upstream["reference"].path / REFERENCE_FILE)
    mask = tuple(config.policy_joints[i] for i in config.residual_indices)
    limits = robot.joint_range[[config.joint_names.index(j) for j in mask]]
    stats = segment_statistics(
        reference.joint_pos, reference.joint_names, reference.fps, mask, limits, p.segment_s, p.min_last_s, p.bins
    )
    stats.save(ctx.out_dir / SEGMENTS_FILE)
    plot_segment_statistics(stats, reference.joint_pos, tuple(leg_joints(robot)), ctx.out_dir / PLOT_FILE)
    ranking = std_ranking(stats, config.policy_joints, mask)
    # The paper's claim is about the lower body: hip and knee pitch spread most among leg joints.
    legs = tuple(j for j in leg_joints(robot) if j in config.policy_joints)
    leg_ranking = std_ranking(stats, legs, mask)
    summary = {
        "segments": stats.n_segments,
        "segment_frames": int(stats.lengths[0]),
        "last_segment_frames": int(stats.lengths[-1]),
        "selected_joints": list(mask),
        "std_ranking": ranking,
        "std_ranking_legs": leg_ranking,
    }
    (ctx.out_dir / SUMMARY_FILE).write_text(json.dumps(summary, indent=2) + "\n")
    ctx.console.print(
        f"  residual mask std ranks: {list(ranking['mask_ranks'].values())} of {len(config.policy_joints)} policy joints, "
        f"{list(leg_ranking['mask_ranks'].values())} of {len(legs)} leg joints"
        f" ({'agrees with' if leg_ranking['agrees'] else 'differs from'} the top {len(mask)} leg joints by std)",
        markup=False,
    )
    return {k: v for k, v in summary.items() if not k.startswith("std_ranking")} | {
        "mask_ranks_by_std": ranking["mask_ranks"],
        "mask_ranks_by_std_legs": leg_ranking["mask_ranks"],
        "mask_agrees_with_std_legs": leg_ranking["agrees"],
        "top_std_joints": ranking["top_k_by_std"],
    }


STAGE = Stage(
    name="stats",
    version=1,
    description="reference -> 1 s segments, joint std, hip/knee-pitch histograms, plot",
    params=StatsConfig,
    provides="segment_stats",
    run=_run,
    inputs=lambda robot, motion: model_files(robot),
    requires=("reference",),
    headline=("segments",),
)
