"""Benchmark: the frames where a robot's pelvis leaves the scaled human's on floor work, and why.

    python -m bench.pelvis_frames [--robot g1] [--clips "ground2_subject2 145-165 s" "ground2_subject3 x0.8 76-96 s" ...]
                                  [--out bench/results/pelvis_frames_g1]

Each clip (a floor cut of a shared take, plain, mirrored or at another tempo, as
`bench/retarget_variants.py` names it) is retargeted with the stage's default params on the robot
and on its wider-ranges copies, and scored frame by frame with the pelvis ruler of
`retarget_quality` (pelvis height against the scaled human's hips, the clip's median offset
removed; bar 0.10 m). The wider-ranges copies are `range_copies` (`bench/retarget_ranges.py`): on
H1 and H1-2, G1's leg ranges, every range 0.5 rad wider, and both; on G1, every range 0.5 rad
wider. Frames over the bar are grouped into stretches, and each says:

- how many of its frames a wider-ranges copy brings within the bar (the ranges explain those);
- of the frames the ranges leave with the robot above the human, how many have a robot body
  other than the feet resting on the floor (sitting on its hip motors: its build stops it going
  lower there, whatever the ranges), and which body;
- how many have a human foot the targets plant while its sole faces more than 90 degrees
  away from the floor (the foot rests on its back: kneeling, lying, crawling; the sole's direction
  is the one that points up while the human stands on that foot, over the whole take);
- how many the IK has lost: the keypoint ruler of `retarget_quality` calls them diverged (the
  robot stuck in another posture, e.g. still lying while the human sits up);
- which leg joints sit at a bound of their range in most of its frames.

Each frame over the bar gets the first of these causes that holds (ranges, body, foot on its
back, lost); the ones with none are left.

The causes after the ranges are read off the robot; what they cost is measured on one more copy,
free of the build: G1's leg ranges, every range 0.5 rad wider, and no body but the feet with any
volume (each collision geom a point at its centre). A frame that copy also leaves over the bar is
not the robot's build, as far as ranges and volume go: it is where the targets and the IK put
the pelvis.

The same seconds are then scored inside the whole take (mirrored or played at the cut's tempo
likewise), retargeted from its start, with the same ruler over those seconds. `<out>.md` is the table, `<out>.json` the numbers.
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

from bench.retarget_ranges import build_free, range_copies
from bench.retarget_variants import BARS, FLOOR_CUT, clips, floor_cut, pelvis_deviation
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.human import HumanMotion
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.lafan_joints import FEET
from rd_pipeline.retarget.quality import QualityThresholds, diverged, quality_series
from rd_pipeline.retarget.retarget import RetargetResult, retarget
from rd_pipeline.retarget.targets import RetargetTargets, resample_human
from rd_pipeline.robots import Robot, load_robot
from rd_pipeline.robots.hulls import BodyHulls

BAR_M = BARS["pelvis_height_dev_p95_m"]
GAP_S = 0.2
"""Stretches over the bar closer than this merge into one."""
BACK_DEG = 90.0
"""A planted human foot whose sole faces farther than this from the floor rests on its back."""
RESTING_M = 0.01
"""A robot body whose lowest point is this close to the floor rests on it."""
CAUSES = ("ranges", "body_rests", "foot_on_back", "lost", "left")
"""Why a frame is over the bar, in the order they are tried (see the module's docstring)."""
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
    resting_body: np.ndarray
    """(T,) the robot body other than the feet lowest above the floor where it is within
    `RESTING_M` of it, else an empty string."""
    lost: np.ndarray
    """(T,) bool: the keypoint ruler calls the frame diverged."""


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
        raise SystemExit(f"--clips {name!r}: give a floor cut as '<take> [mirrored|x<tempo>] <start>-<end> s'")
    take, *perturbed = parts[0].split(" ")
    span = parts[1]
    whole_variant = whole_take_variant(perturbed)
    clip = floor_cut(take, name, f"floor_cut_{whole_variant}".removesuffix("_plain"))
    own_result = retarget(clip, robot, RetargetConfig())
    own = _scored(robot, own_result)
    wider = {
        copy_name: pelvis_deviation(copy, retarget(clip, copy, RetargetConfig()))
        for copy_name, copy in range_copies(robot).items()
    }
    free_robot = build_free(robot)
    free = pelvis_deviation(free_robot, retarget(clip, free_robot, RetargetConfig()))
    whole_human = clips(take, whole_variant)[0][1]
    whole_result = retarget(whole_human, robot, RetargetConfig())
    soles = sole_directions(whole_human, whole_result.targets)
    on_back = planted_on_back(clip, own_result.targets, soles)
    fps = own_result.reference.fps
    over = np.abs(own.deviation) > BAR_M
    cause = _causes(own, list(wider.values()), on_back)
    stretches = [_stretch(robot, own, cause, frames, fps) for frames in _over_bar(own, fps)]
    start_s = float(span.split("-")[0])
    whole = _within_whole_take(robot, whole_result, start_s, len(own.deviation))
    return {
        "clip": name,
        "frames": len(over),
        "pelvis_p95_m": _p95(own.deviation),
        "wider_ranges_p95_m": {copy_name: _p95(deviation) for copy_name, deviation in wider.items()},
        "frames_over": int(over.sum()),
        **{f"over_{key}": int((over & (cause == key)).sum()) for key in CAUSES},
        "build_free_p95_m": _p95(free),
        "over_past_build_free": int((over & (cause != "ranges") & (np.abs(free) > BAR_M)).sum()),
        "cut_frames_foot_on_back": int(on_back.sum()),
        "whole_take_same_seconds_p95_m": whole,
        "stretches": stretches,
    }


def whole_take_variant(perturbed: list[str]) -> str:
    """The `bench.retarget_variants` variant of the whole take that a floor cut's name says it was
    cut from (`perturbed`: the words between the take and the seconds)."""
    if not perturbed:
        return "plain"
    if perturbed == ["mirrored"]:
        return "mirror"
    if len(perturbed) == 1 and perturbed[0].startswith("x"):
        return f"tempo_{perturbed[0].removeprefix('x')}"
    raise PipelineError(f"'{' '.join(perturbed)}' names no perturbation (mirrored, x<tempo>)")


def _causes(own: _Scored, wider: list[np.ndarray], on_back: np.ndarray) -> np.ndarray:
    """(T,) per frame, the first of `CAUSES` that holds ("left" where none does); the ranges hold
    where any wider-ranges copy (`wider`, each (T,)) is within the bar."""
    holds = {
        "ranges": np.any(np.abs(np.stack(wider)) <= BAR_M, axis=0),
        "body_rests": (own.deviation > 0) & (own.resting_body != ""),
        "foot_on_back": on_back,
        "lost": own.lost,
    }
    cause = np.full(len(on_back), "left", dtype=object)
    for key in reversed(CAUSES[:-1]):
        cause[holds[key]] = key
    return cause


def _scored(robot: Robot, result: RetargetResult) -> _Scored:
    human_pelvis = result.targets.human_pelvis
    reference = result.reference
    targets = result.targets
    series = quality_series(robot, reference, targets.positions, targets.bodies, human_pelvis)
    deviation = series["pelvis_height_dev_m"]
    lower, upper = robot.retarget_range.T
    joints = reference.joint_pos
    at_bound = (joints - lower < BOUND_RAD) | (upper - joints < BOUND_RAD)
    hulls = BodyHulls.from_robot(robot).without(robot.config.foot_bodies)
    lowest = hulls.lowest_z(reference.body_pos_w, reference.body_quat_w, reference.body_names)
    names = np.array(hulls.body_names, dtype=object)
    resting = np.where(lowest.min(axis=1) < RESTING_M, names[lowest.argmin(axis=1)], "")
    lost = diverged(series["keypoint_error_m"], QualityThresholds())
    return _Scored(deviation, human_pelvis[:, 2], at_bound, resting, lost)


def sole_directions(human: HumanMotion, targets: RetargetTargets) -> np.ndarray:
    """(2, 3) the left and right sole's direction in the human foot joint's frame: the axis that
    points up, on average, over the frames `targets` (of `human`) plant that foot while the human
    stands. Read on a whole take: a floor cut may never stand."""
    _, rotations, names = resample_human(human, targets.fps)
    soles = []
    for side, foot in enumerate(FEET):
        flat = targets.foot_contact[:, side].astype(bool) & targets.human_standing
        if not flat.any():
            raise PipelineError(f"the human never stands on the {foot} foot: no sole direction to learn")
        turns = rotations[: len(flat), names.index(foot)][flat]
        up = (turns.transpose(0, 2, 1) @ np.array([0.0, 0.0, 1.0])).mean(axis=0)
        soles.append(up / np.linalg.norm(up))
    return np.array(soles)


def planted_on_back(clip: HumanMotion, targets: RetargetTargets, soles: np.ndarray) -> np.ndarray:
    """(T,) bool: the targets plant a human foot whose sole (`soles`, from `sole_directions`)
    faces away from the floor by more than `BACK_DEG`."""
    _, rotations, names = resample_human(clip, targets.fps)
    planted = targets.foot_contact.astype(bool)
    on_back = np.zeros(len(planted), dtype=bool)
    for side, foot in enumerate(FEET):
        turns = rotations[: len(planted), names.index(foot)]
        facing_up = (turns @ soles[side])[:, 2]
        on_back |= planted[:, side] & (facing_up < np.cos(np.radians(BACK_DEG)))
    return on_back


def _over_bar(own: _Scored, fps: float) -> list[np.ndarray]:
    """Frame indices of each stretch over the bar."""
    over = np.flatnonzero(np.abs(own.deviation) > BAR_M)
    if len(over) == 0:
        return []
    gap = max(1, round(GAP_S * fps))
    return np.split(over, np.flatnonzero(np.diff(over) > gap) + 1)


def _stretch(robot: Robot, own: _Scored, cause: np.ndarray, frames: np.ndarray, fps: float) -> dict:
    held = own.at_bound[frames].mean(axis=0)
    names = robot.config.joint_names
    legs = [
        names[j]
        for j in np.argsort(-held)
        if held[j] > 0.5 and ("hip" in names[j] or "knee" in names[j] or "ankle" in names[j])
    ]
    rests = own.resting_body[frames][cause[frames] == "body_rests"]
    bodies, counts = np.unique(rests.astype(str), return_counts=True)
    return {
        "seconds": [round(frames[0] / fps, 2), round((frames[-1] + 1) / fps, 2)],
        "frames": len(frames),
        "human_hips_m": round(float(own.hips[frames].mean()), 3),
        "deviation_m": round(float(own.deviation[frames].mean()), 3),
        **{key: int((cause[frames] == key).sum()) for key in CAUSES},
        "resting_on": [str(b) for b in bodies[np.argsort(-counts)]],
        "legs_at_bound": legs,
    }


def _within_whole_take(robot: Robot, result: RetargetResult, start_s: float, frames: int) -> float:
    """The pelvis ruler over the cut's seconds inside the whole take, retargeted from its start."""
    first = round(start_s * result.reference.fps)
    window = pelvis_deviation(robot, result)[first : first + frames]
    return _p95(window - np.median(window))


def _copies(report: dict) -> str:
    return ", ".join(f"{name} {p95:.3f}" for name, p95 in report["wider_ranges_p95_m"].items())


def _p95(deviation: np.ndarray) -> float:
    return round(float(np.percentile(np.abs(deviation), 95.0)), 3)


def _markdown(robot: str, reports: list[dict]) -> str:
    lines = [
        f"# {robot}: pelvis frames over {BAR_M:g} m on floor cuts ({FLOOR_CUT['length_s']:g} s), and why",
        "",
        "Each frame over the bar counts under the first cause that holds: the wider ranges bring it within "
        "the bar; the robot is above the human with a body other than the feet resting on the floor; a "
        "human foot is planted on its back; the keypoint ruler calls the frame diverged (lost); none (left).",
        "",
    ]
    for report in reports:
        lines += [
            f"## {report['clip']}",
            "",
            f"Pelvis p95 {report['pelvis_p95_m']:.3f} m (wider ranges {_copies(report)}; the same seconds "
            f"within the whole take {report['whole_take_same_seconds_p95_m']:.3f}). {report['frames_over']} of "
            f"{report['frames']} frames over the bar: ranges {report['over_ranges']}, robot resting on its body "
            f"{report['over_body_rests']}, foot on its back {report['over_foot_on_back']}, lost {report['over_lost']}, "
            f"left {report['over_left']} "
            f"({report['cut_frames_foot_on_back']} frames of the cut have a foot planted on its back). "
            f"The build-free copy: p95 {report['build_free_p95_m']:.3f} m; of the frames the ranges leave, "
            f"{report['over_past_build_free']} are over the bar on it too.",
            "",
            "| seconds | frames | human hips m | robot - human m | ranges | body rests (on) | foot on its back | lost "
            "| left | legs at a bound |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for stretch in report["stretches"]:
            start, end = stretch["seconds"]
            on = ", ".join(stretch["resting_on"])
            lines.append(
                f"| {start:.2f}-{end:.2f} | {stretch['frames']} | {stretch['human_hips_m']:.3f} | "
                f"{stretch['deviation_m']:+.3f} | {stretch['ranges']} | {stretch['body_rests']}"
                f"{f' ({on})' if on else ''} | {stretch['foot_on_back']} | {stretch['lost']} | {stretch['left']} | "
                f"{', '.join(stretch['legs_at_bound']) or '-'} |"
            )
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
