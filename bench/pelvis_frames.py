"""Benchmark: the frames where a robot's pelvis leaves the scaled human's on floor work, and why.

    python -m bench.pelvis_frames [--robot g1] [--clips "ground2_subject2 145-165 s" ...]
                                  [--out bench/results/pelvis_frames_g1]

Each clip (a floor cut of a shared take, `bench/retarget_variants.py`) is retargeted with the
stage's default params on the robot and on its wider-ranges copy, and scored frame by frame with
the pelvis ruler of `retarget_quality` (pelvis height against the scaled human's hips, the clip's
median offset removed; bar 0.10 m). Frames over the bar are grouped into stretches, and each says:

- how many of its frames the wider-ranges copy brings within the bar (the ranges explain those);
- how many have a human foot the targets plant while its sole faces more than 90 degrees
  away from the floor (the foot rests on its back: kneeling, lying, crawling; the sole's direction
  is the one that points up while the human stands on that foot);
- which leg joints sit at a bound of their range in most of its frames.

The same seconds are then scored inside the whole take, retargeted from its start, with the same
ruler over those seconds. `<out>.md` is the table, `<out>.json` the numbers.
"""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from bench.retarget_variants import BARS, FLOOR_CUT, _wider_ranges, clips, floor_cut
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.human import HumanMotion
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.lafan_joints import FEET
from rd_pipeline.retarget.quality import quality_series
from rd_pipeline.retarget.retarget import RetargetResult, retarget
from rd_pipeline.retarget.targets import RetargetTargets, resample_human
from rd_pipeline.robots import Robot, load_robot

BAR_M = BARS["pelvis_height_dev_p95_m"]
GAP_S = 0.2
"""Stretches over the bar closer than this merge into one."""
BACK_DEG = 90.0
"""A planted human foot whose sole faces farther than this from the floor rests on its back."""
STANDING = 0.8
"""The human stands while the hips are above this fraction of their highest in the clip."""
BOUND_RAD = 0.02
"""A joint this close to a bound of its range sits at the bound."""


@dataclass(frozen=True)
class _Scored:
    """One retarget of a clip, frame by frame."""

    deviation: np.ndarray
    """(T,) pelvis height minus the scaled human's hips, the median offset removed (m)."""
    hips: np.ndarray
    """(T,) the scaled human's hips height (m)."""
    at_bound: np.ndarray
    """(T, J) bool: joint at a bound of the robot's range."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--clips", nargs="+", default=["ground2_subject2 145-165 s"])
    parser.add_argument("--out", type=Path, default=Path("bench/results/pelvis_frames_g1"))
    args = parser.parse_args()
    try:
        robot = load_robot(args.robot)
        reports = [_report(robot, name) for name in args.clips]
    except PipelineError as exc:
        raise SystemExit(f"pelvis_frames: {exc}") from None
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(reports, indent=1) + "\n")
    args.out.with_suffix(".md").write_text(_markdown(args.robot, reports))


def _report(robot: Robot, name: str) -> dict:
    parts = name.rsplit(" ", 2)
    if len(parts) != 3:
        raise SystemExit(f"--clips {name!r}: give a floor cut as '<take> <start>-<end> s'")
    take, span, _ = parts
    clip = floor_cut(take, name)
    own_result = retarget(clip, robot, RetargetConfig())
    own = _scored(robot, own_result)
    wider_robot = _wider_ranges(robot)
    wider = _scored(wider_robot, retarget(clip, wider_robot, RetargetConfig()))
    on_back = planted_on_back(clip, own_result.targets)
    stretches = [
        _stretch(robot, own, wider, on_back, frames, own_result.reference.fps) for frames in _over_bar(own, own_result)
    ]
    start_s = float(span.split("-")[0])
    whole = _within_whole_take(robot, take, start_s, len(own.deviation), own_result.reference.fps)
    over = np.abs(own.deviation) > BAR_M
    explained = over & (np.abs(wider.deviation) <= BAR_M)
    return {
        "clip": name,
        "frames": len(over),
        "pelvis_p95_m": _p95(own.deviation),
        "wider_ranges_p95_m": _p95(wider.deviation),
        "frames_over": int(over.sum()),
        "over_ranges_explain": int(explained.sum()),
        "over_foot_on_back": int((over & on_back).sum()),
        "over_unexplained_foot_on_back": int((over & ~explained & on_back).sum()),
        "cut_frames_foot_on_back": int(on_back.sum()),
        "whole_take_same_seconds_p95_m": whole,
        "stretches": stretches,
    }


def _scored(robot: Robot, result: RetargetResult) -> _Scored:
    human_pelvis = result.targets.human_pelvis
    deviation = quality_series(robot, result.reference, human_pelvis=human_pelvis)["pelvis_height_dev_m"]
    lower, upper = robot.retarget_range.T
    joints = result.reference.joint_pos
    at_bound = (joints - lower < BOUND_RAD) | (upper - joints < BOUND_RAD)
    return _Scored(deviation, human_pelvis[:, 2], at_bound)


def planted_on_back(clip: HumanMotion, targets: RetargetTargets) -> np.ndarray:
    """(T,) bool: the targets plant a human foot whose sole faces away from the floor by more than
    `BACK_DEG`. A foot's sole direction (in its own frame) is the one that points up, on
    average, over the frames the targets plant it while the human stands."""
    _, rotations, names = resample_human(clip, targets.fps)
    planted = targets.foot_contact.astype(bool)
    hips = targets.human_pelvis[:, 2]
    standing = hips >= STANDING * hips.max()
    on_back = np.zeros(len(planted), dtype=bool)
    for side, foot in enumerate(FEET):
        turns = rotations[: len(planted), names.index(foot)]
        flat = planted[:, side] & standing
        normal = (turns[flat].transpose(0, 2, 1) @ np.array([0.0, 0.0, 1.0])).mean(axis=0)
        facing_up = (turns @ (normal / np.linalg.norm(normal)))[:, 2]
        on_back |= planted[:, side] & (facing_up < np.cos(np.radians(BACK_DEG)))
    return on_back


def _over_bar(own: _Scored, result: RetargetResult) -> list[np.ndarray]:
    """Frame indices of each stretch over the bar."""
    over = np.flatnonzero(np.abs(own.deviation) > BAR_M)
    if len(over) == 0:
        return []
    gap = max(1, round(GAP_S * result.reference.fps))
    return np.split(over, np.flatnonzero(np.diff(over) > gap) + 1)


def _stretch(robot: Robot, own: _Scored, wider: _Scored, on_back: np.ndarray, frames: np.ndarray, fps: float) -> dict:
    held = own.at_bound[frames].mean(axis=0)
    names = robot.config.joint_names
    legs = [
        names[j]
        for j in np.argsort(-held)
        if held[j] > 0.5 and ("hip" in names[j] or "knee" in names[j] or "ankle" in names[j])
    ]
    return {
        "seconds": [round(frames[0] / fps, 2), round((frames[-1] + 1) / fps, 2)],
        "frames": len(frames),
        "human_hips_m": round(float(own.hips[frames].mean()), 3),
        "deviation_m": round(float(own.deviation[frames].mean()), 3),
        "wider_ranges_within_bar": int((np.abs(wider.deviation[frames]) <= BAR_M).sum()),
        "foot_on_back": int(on_back[frames].sum()),
        "legs_at_bound": legs,
    }


def _within_whole_take(robot: Robot, take: str, start_s: float, frames: int, fps: float) -> float:
    """The pelvis ruler over the cut's seconds inside the whole take, retargeted from its start."""
    result = retarget(clips(take, "plain")[0][1], robot, RetargetConfig())
    scored = _scored(robot, result)
    first = round(start_s * fps)
    window = scored.deviation[first : first + frames]
    return _p95(window - np.median(window))


def _p95(deviation: np.ndarray) -> float:
    return round(float(np.percentile(np.abs(deviation), 95.0)), 3)


def _markdown(robot: str, reports: list[dict]) -> str:
    lines = [f"# {robot}: pelvis frames over {BAR_M:g} m on floor cuts ({FLOOR_CUT['length_s']:g} s), and why", ""]
    for report in reports:
        lines += [
            f"## {report['clip']}",
            "",
            f"Pelvis p95 {report['pelvis_p95_m']:.3f} m (wider ranges {report['wider_ranges_p95_m']:.3f}; the same seconds "
            f"within the whole take {report['whole_take_same_seconds_p95_m']:.3f}). {report['frames_over']} of "
            f"{report['frames']} frames over the bar: the wider ranges bring {report['over_ranges_explain']} within it; "
            f"{report['over_foot_on_back']} have a human foot planted on its back "
            f"({report['over_unexplained_foot_on_back']} of those the ranges leave; "
            f"{report['cut_frames_foot_on_back']} such frames in the cut).",
            "",
            "| seconds | frames | human hips m | robot - human m | wider ranges within bar | foot on its back | legs at a bound |",
            "|---|---|---|---|---|---|---|",
        ]
        for stretch in report["stretches"]:
            start, end = stretch["seconds"]
            lines.append(
                f"| {start:.2f}-{end:.2f} | {stretch['frames']} | {stretch['human_hips_m']:.3f} | "
                f"{stretch['deviation_m']:+.3f} | {stretch['wider_ranges_within_bar']} | {stretch['foot_on_back']} | "
                f"{', '.join(stretch['legs_at_bound']) or '-'} |"
            )
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
