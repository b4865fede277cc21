"""Benchmark: how much of H1's and H1-2's retarget misses their narrow leg joint ranges explain.

    python bench/retarget_leg_ranges.py [--robots h1 h1_2] [--motions dance1_subject1 ...] [--resume]
                                        [--out bench/results/retarget_leg_ranges]

H1 and H1-2 turn and spread their hips only ±0.43 rad (G1: ±2.76 yaw, -0.52..2.97 roll) and bend
their knees to 2.05 / 2.19 rad (G1: 2.88). For each (robot, take) this retargets the BVH twice with
the stage's default params, once on the robot's own model and once on a copy whose hip yaw, hip
roll and knee ranges are G1's, and scores both with the same ruler. What the copy fixes is what
the ranges cost; what it leaves is the retargeter's. The copy is a counterfactual, not a robot:
its joint-limit column is measured against its own (wider) ranges. Each finished row is appended
to `<out>.jsonl`; `<out>.md` is written at the end.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import os
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from retarget import TAKES  # bench/retarget.py: the nine shared takes

from rd_pipeline import paths
from rd_pipeline.evaluation.retarget_quality import retarget_quality
from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, human_motion_from_bvh
from rd_pipeline.retarget.retarget import retarget
from rd_pipeline.retarget.settings import RetargetParams
from rd_pipeline.robots import Robot, load_robot

WIDENED = ("hip_yaw", "hip_roll", "knee")
"""Joint kinds whose ranges the counterfactual takes from G1."""
COLUMNS = {
    "diverged_frames": "diverged",
    "pelvis_height_dev_p95_m": "pelvis dev p95",
    "skate_stance_mean_mm_s": "skate",
    "keypoint_error_mean_mm": "kp mean",
    "keypoint_error_max_mm": "kp max",
    "penetration_max_mm": "pen max",
    "self_collision_frames": "self-coll",
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=["h1", "h1_2"])
    parser.add_argument("--motions", nargs="+", default=TAKES)
    parser.add_argument("--resume", action="store_true", help="keep the rows already in <out>.jsonl")
    parser.add_argument("--out", type=Path, default=Path("bench/results/retarget_leg_ranges"))
    args = parser.parse_args()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    log = args.out.with_suffix(".jsonl")
    rows = []
    if args.resume and log.exists():
        rows = [json.loads(line) for line in log.read_text().splitlines()]
    else:
        log.write_text("")
    done = {(row["robot"], row["motion"]) for row in rows}
    for motion in args.motions:
        human = human_motion_from_bvh(read_bvh(paths.bvh_path(motion)), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
        for robot_name in args.robots:
            if (robot_name, motion) in done:
                continue
            robot = load_robot(robot_name)
            row = {
                "robot": robot_name,
                "motion": motion,
                "own_ranges": _score(human, robot),
                "g1_leg_ranges": _score(human, with_g1_leg_ranges(robot)),
            }
            rows.append(row)
            with log.open("a") as file:
                file.write(json.dumps(row) + "\n")
            print(f"{robot_name:<5} {motion:<26} " + _change(row, "diverged_frames"), flush=True)
    args.out.with_suffix(".md").write_text(_table(rows))
    print(_table(rows))


def with_g1_leg_ranges(robot: Robot) -> Robot:
    """A copy of `robot` whose hip yaw, hip roll and knee ranges are G1's (same side, same joint kind)."""
    g1 = load_robot("g1")
    model = copy.deepcopy(robot.model)
    for name in robot.config.joint_names:
        kind = next((k for k in WIDENED if f"_{k}_" in f"_{name}"), None)
        if kind is None:
            continue
        side = name.split("_")[0]
        model.jnt_range[model.joint(name).id] = g1.model.jnt_range[g1.model.joint(f"{side}_{kind}_joint").id]
    return dataclasses.replace(robot, model=model)


def _score(human, robot: Robot) -> dict:
    result = retarget(human, robot, RetargetParams())
    quality = retarget_quality(
        robot,
        result.reference,
        keypoint_targets=result.targets.positions,
        keypoint_bodies=result.targets.bodies,
        human_pelvis=result.targets.human_pelvis,
    )
    return {key: quality[key] for key in COLUMNS}


def _change(row: dict, key: str) -> str:
    return f"{COLUMNS[key]} {row['own_ranges'][key]} -> {row['g1_leg_ranges'][key]}"


def _table(rows: list[dict]) -> str:
    lines = [
        "| robot | take | " + " | ".join(f"{label}: own → G1 legs" for label in COLUMNS.values()) + " |",
        "|" + "---|" * (len(COLUMNS) + 2),
    ]
    for row in rows:
        cells = [f"{_cell(row['own_ranges'][key], key)} → {_cell(row['g1_leg_ranges'][key], key)}" for key in COLUMNS]
        lines.append(f"| {row['robot']} | {row['motion']} | " + " | ".join(cells) + " |")
    for robot in sorted({row["robot"] for row in rows}):
        own = sum(row["own_ranges"]["diverged_frames"] for row in rows if row["robot"] == robot)
        widened = sum(row["g1_leg_ranges"]["diverged_frames"] for row in rows if row["robot"] == robot)
        lines.append(f"| {robot} | all takes | {own} → {widened} |" + " |" * (len(COLUMNS) - 1))
    lines.append("")
    lines.append(f"Each cell: the robot's own model → a copy with G1's {', '.join(WIDENED)} ranges.")
    lines.append("Pelvis deviation in m, skate in mm/s, keypoint error and penetration in mm.")
    return "\n".join(lines) + "\n"


def _cell(value: float, key: str) -> str:
    if key == "pelvis_height_dev_p95_m":
        return f"{value:.3f}"
    if isinstance(value, float):
        return f"{value:.1f}"
    return str(value)


if __name__ == "__main__":
    main()
