"""Benchmark: where learning starts on a clip, as survival of zero outputs on the training model.

    python -m studies.initial_policy [--windows g1:dance1_subject2:11:21 h1_2:dance2_subject4:193:203 ...]
        [--starts 10] [--modes selective all selective:z] [--out studies/results/initial_policy]

A freshly initialized actor outputs about zero. Under `selective` (the paper's mask) that holds
every joint but hip and knee pitch at the default pose while the reference dances; under `all`
it feeds the reference to PD, the validation's zero-action baseline. `selective:z` is the paper's
mask with height-only motion-far terminations (`motion_far_height_only`, the anchors' lenient
ones). For each window this rolls out zero outputs under each mode from `--starts` evenly spaced
frames on the nominal training model (primitive collision, training terminations, no
randomization) and writes the seconds survived per start, with the reference's joint speed (p95
per second) and footing per second (the share of frames with a foot planted, and the median tilt
of the lowest foot: a flat-soled robot cannot stand on a sole's edge). Writes `<out>.json` and
`<out>.md`.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
from pathlib import Path
from typing import Any

import torch

from bench.common import write_result
from rd_pipeline.api import workspace
from rd_pipeline.env.config import EnvConfig
from rd_pipeline.env.tracking_env import TrackingEnv
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.activity import joint_speed_p95_per_second
from rd_pipeline.motion.footing import footing_per_second
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.robots import Robot, load_robot
from rd_pipeline.sampling.sampler import SamplerConfig, SegmentSampler
from rd_pipeline.sampling.segments import segment_bounds
from rd_pipeline.training.config import clip_frames
from rd_pipeline.training.evaluate import nominal, scoring_starts, survival, zero_action

WINDOWS = ("g1:dance1_subject2:11:21", "h1_2:dance2_subject4:193:203")
"""The CPU and GPU dance windows of issue 31: G1's study window and H1-2's busiest ten seconds."""


def main() -> None:
    args = _parser().parse_args()
    try:
        rows = [_window(window, args.modes, args.starts) for window in args.windows]
    except (PipelineError, ValueError) as exc:
        sys.exit(f"error: {exc}")
    result = {"starts": args.starts, "modes": args.modes, "windows": rows}
    write_result(args.out, result, _table(result))


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--windows",
        nargs="+",
        default=list(WINDOWS),
        help="robot:motion:start:end (seconds), `:bvh` or `:csv` appended to choose the reference's source",
    )
    parser.add_argument(
        "--modes",
        nargs="+",
        default=["selective", "all", "selective:z"],
        help="action modes (residual presets); `:z` appended: height-only motion-far terminations",
    )
    parser.add_argument("--starts", type=int, default=10)
    parser.add_argument("--out", type=Path, default=Path("studies/results/initial_policy"))
    return parser


def _window(window: str, modes: list[str], starts: int) -> dict[str, Any]:
    robot_name, motion, start_s, end_s, source = _split(window)
    clip = f"{start_s}:{end_s}"
    reference, resolved = _reference(robot_name, motion, clip, source)
    robot = load_robot(robot_name)
    survival_s = {mode: _zero_output_survival(robot, reference, mode, starts) for mode in modes}
    footing = footing_per_second(reference, robot.config.foot_bodies)
    return {
        "robot": robot_name,
        "motion": motion,
        "clip": clip,
        "source": resolved,
        "survival_s": survival_s,
        "median_s": {mode: statistics.median(values) for mode, values in survival_s.items()},
        "reference_joint_speed_p95_by_second": joint_speed_p95_per_second(reference),
        "reference_planted_share_by_second": [second.planted_share for second in footing],
        "reference_lowest_foot_tilt_deg_by_second": [second.lowest_foot_tilt_deg for second in footing],
    }


def _split(window: str) -> tuple[str, str, str, str, str | None]:
    parts = window.split(":")
    if len(parts) not in (4, 5) or parts[4:] not in ([], ["bvh"], ["csv"]):
        raise ValueError(f"--windows {window!r}: expected robot:motion:start:end[:bvh|:csv]")
    source = parts[4] if len(parts) == 5 else None
    return parts[0], parts[1], parts[2], parts[3], source


def _reference(robot: str, motion: str, clip: str, source: str | None) -> tuple[ReferenceMotion, str]:
    """The clip of the reference the pipeline trains on (made up to `prior` if not yet there), and
    its source (`bvh` or `csv`; by default BVH where the take has one)."""
    plan = workspace.plan(robot, motion, "cpu", source=source)
    workspace.run(plan, until="prior", resume=True)
    reference = workspace.reference(plan)
    start, end = clip_frames(clip, reference.fps, reference.n_frames)
    return reference.frames(start, end), plan.pipeline.source


def _zero_output_survival(robot: Robot, reference: ReferenceMotion, variant: str, starts: int) -> list[float]:
    """`variant`: an action mode, `:z` appended for height-only motion-far terminations."""
    mode, _, axes = variant.partition(":")
    segment_starts, lengths = segment_bounds(reference.n_frames, reference.fps, 1.0, 0.25)
    sampler = SegmentSampler(SamplerConfig(), torch.ones(len(segment_starts)), seed=0)
    base = EnvConfig(backend="cpu")
    terminations = dataclasses.replace(base.terminations, motion_far_height_only=axes == "z")
    actions = dataclasses.replace(base.actions, mode=mode)
    config = nominal(dataclasses.replace(base, actions=actions, terminations=terminations), starts)
    env = TrackingEnv(robot, reference, sampler, segment_starts, lengths, config, seed=0)
    seconds = survival(env, zero_action(env.num_actions), scoring_starts(env.max_episode_length, starts))
    return [round(float(value), 2) for value in seconds]


def _table(result: dict[str, Any]) -> str:
    modes = result["modes"]
    lines = [
        "# Zero outputs on the nominal training model: seconds survived per start",
        "",
        "| robot | motion | clip (source) | joint speed p95 (rad/s, per second) | planted share (per second) "
        "| lowest-foot tilt (deg, per second) | " + " | ".join(f"{mode} (median; per start)" for mode in modes) + " |",
        "|---|---|---|---|---|---|" + "---|" * len(modes),
    ]
    for row in result["windows"]:
        speeds = ", ".join(f"{value:.1f}" for value in row["reference_joint_speed_p95_by_second"])
        planted = ", ".join(f"{value:.2f}" for value in row["reference_planted_share_by_second"])
        tilts = ", ".join(f"{value:.0f}" for value in row["reference_lowest_foot_tilt_deg_by_second"])
        cells = [
            f"{row['median_s'][mode]:.2f}; {', '.join(f'{v:.2f}' for v in row['survival_s'][mode])}" for mode in modes
        ]
        clip = f"{row['clip']} ({row['source']})"
        head = f"| {row['robot']} | {row['motion']} | {clip} | {speeds} | {planted} | {tilts} | "
        lines.append(head + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
