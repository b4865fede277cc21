"""Benchmark: where the foot skate of the floor cuts that miss its bar comes from.

    python -m bench.floor_skate_sources [--rows bench/results/retarget_variants_stage20_floor.jsonl]
                                        [--bar 15] [--near 0.015] [--out bench/results/floor_skate_sources]

Every row of `--rows` (a `retarget_variants` log) whose skate misses `--bar` is retargeted again
and its skate split by frame. The ruler averages the horizontal speed of each foot over the frames
its sole is within 2 cm of the floor; here that speed's sum is divided among three kinds of frame:
planted by the targets with the foot within `--near` of its target (jitter about a held point),
planted and farther (a point the legs do not reach), and not planted (the targets' swing, a foot
leaving or landing along the floor). The shares say which repair the row needs.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bench.retarget import retarget_and_score
from bench.retarget_variants import clips
from rd_pipeline.retarget.quality import QualityThresholds, sole_heights_and_speeds
from rd_pipeline.robots import load_robot


def main() -> None:
    args = _parser().parse_args()
    if not args.rows.is_file():
        raise SystemExit(f"{args.rows}: no such retarget_variants log")
    rows = [json.loads(line) for line in args.rows.read_text().splitlines()]
    missing = [row for row in rows if row["ours"]["skate_stance_mean_mm_s"] > args.bar]
    out = [_sources(row, args.near) for row in missing]
    args.out.with_suffix(".jsonl").write_text("".join(json.dumps(row) + "\n" for row in out))
    args.out.with_suffix(".md").write_text(_table(out, args))


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split(".")[0])
    parser.add_argument("--rows", type=Path, default=Path("bench/results/retarget_variants_stage20_floor.jsonl"))
    parser.add_argument("--bar", type=float, default=15.0, help="skate bar, mm/s")
    parser.add_argument("--near", type=float, default=0.015, help="a planted foot this close to its target (m)")
    parser.add_argument("--out", type=Path, default=Path("bench/results/floor_skate_sources"))
    return parser


def _sources(row: dict, near_m: float) -> dict:
    """The row's clip retargeted again, its skate split into the three kinds of frame."""
    robot = load_robot(row["robot"])
    clip = dict(clips(row["take"], row["variant"]))[row["clip"]]
    result, quality, _ = retarget_and_score(clip, robot)
    reference = result.reference
    targets = result.targets
    soles, speed = sole_heights_and_speeds(robot, reference)
    stance = soles < QualityThresholds().ground_contact_height_m
    feet = robot.config.foot_bodies
    reached = reference.body_pos_w[:, [reference.body_names.index(foot) for foot in feet], :2]
    aimed = targets.positions[:, [targets.bodies.index(foot) for foot in feet], :2]
    near = np.linalg.norm(reached - aimed, axis=-1) <= near_m
    planted = targets.foot_contact.astype(bool)
    total = float(speed[stance].sum())
    kinds = {"planted_near": planted & near, "planted_far": planted & ~near, "not_planted": ~planted}
    return {
        "robot": row["robot"],
        "clip": row["clip"],
        "skate_mm_s": quality["skate_stance_mean_mm_s"],
        "stance_frames": int(stance.sum()),
        **{f"{kind}_frames": int((stance & where).sum()) for kind, where in kinds.items()},
        **{f"{kind}_share": round(float(speed[stance & where].sum()) / total, 3) for kind, where in kinds.items()},
    }


def _table(rows: list[dict], args: argparse.Namespace) -> str:
    near = f"{args.near * 1000:g} mm"
    lines = [
        f"Floor cuts of `{args.rows}` over the {args.bar:g} mm/s skate bar: where the skate comes from",
        "(share of the summed sole speed over stance frames; frames in brackets).",
        "",
        f"| robot | clip | skate mm/s | planted, within {near} | planted, farther | not planted |",
        "|---|---|---|---|---|---|",
    ]
    for row in sorted(rows, key=lambda row: -row["skate_mm_s"]):
        shares = " | ".join(
            f"{row[f'{kind}_share']:.2f} ({row[f'{kind}_frames']})"
            for kind in ("planted_near", "planted_far", "not_planted")
        )
        lines.append(f"| {row['robot']} | {row['clip']} | {row['skate_mm_s']:.1f} | {shares} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
