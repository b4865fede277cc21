"""Benchmark: how much of each robot's retarget misses its joint ranges explain.

    python -m bench.retarget_ranges [--robots g1 h1 h1_2] [--motions dance1_subject1 ...] [--widen-rad 0.5]
                                    [--jobs 2] [--resume] [--out bench/results/retarget_ranges]

Each (robot, take) is retargeted with the stage's default params on the robot's own model and on
counterfactual copies, and all are scored with the same ruler (`bench/retarget.py`):

- `widened`: every joint range grown by `--widen-rad` at both ends. It needs no convention shared
  between robots, so it applies to all three;
- `g1_legs` (H1 and H1-2 only): hip yaw, hip roll and knee ranges taken from G1 (same side, same
  joint kind). H1 turns and spreads its hips only ±0.43 rad and bends its knees to 2.05 rad.

Two more copies are not in this table: `free_ranges` takes G1's legs and widens every range 0.5 rad
more (with `g1_legs` and `widened`, one of the copies `bench/retarget_variants.py` asks whether
ranges explain a pelvis miss: `range_copies`), and `build_free` also leaves no body but the feet
any volume, so nothing of the robot's build holds it back (`bench/pelvis_frames.py`,
`bench/retarget_variants.py --build-free`).

What a copy fixes is what the ranges cost; what it leaves is the retargeter's (or the rest of the
robot's build, e.g. H1's single-axis ankle). A copy is not a robot: its joint-limit column is
measured against its own wider ranges. Each finished row is appended to `<out>.jsonl`; `<out>.md`
is written at the end.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import mujoco
import numpy as np

from bench.retarget import in_take_order, pending, resume_log, retarget_and_score, shared_takes
from rd_pipeline import paths
from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, human_motion_from_bvh
from rd_pipeline.robots import Robot, load_robot

G1_LEG_KINDS = ("hip_yaw", "hip_roll", "knee")
"""Joint kinds whose ranges the `g1_legs` copy takes from G1."""
BUILD_FREE_WIDEN_RAD = 0.5
"""How much wider than G1's leg ranges every range of the build-free copy is, at both ends."""
VARIANTS = ("own", "g1_legs", "widened")
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
    parser.add_argument("--robots", nargs="+", default=["g1", "h1", "h1_2"])
    parser.add_argument("--motions", nargs="+", default=shared_takes())
    parser.add_argument("--widen-rad", type=float, default=0.5, help="growth of every range at each end")
    parser.add_argument("--jobs", type=int, default=2, help="(robot, take) rows computed at once")
    parser.add_argument("--resume", action="store_true", help="keep the rows already in <out>.jsonl")
    parser.add_argument("--out", type=Path, default=Path("bench/results/retarget_ranges"))
    args = parser.parse_args()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    log = args.out.with_suffix(".jsonl")
    rows = resume_log(log, args.resume)
    todo = pending(rows, args.motions, args.robots)
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(_row, robot, motion, args.widen_rad) for robot, motion in todo]
        for future in as_completed(futures):
            row = future.result()
            rows.append(row)
            with log.open("a") as file:
                file.write(json.dumps(row) + "\n")
            print(f"{row['robot']:<5} {row['motion']:<26} diverged {_change(row, 'diverged_frames')}", flush=True)
    rows = in_take_order(rows, args.motions, args.robots)
    args.out.with_suffix(".md").write_text(_table(rows, args.widen_rad))
    print(_table(rows, args.widen_rad))


def _row(robot_name: str, motion: str, widen_rad: float) -> dict:
    human = human_motion_from_bvh(read_bvh(paths.bvh_path(motion)), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
    robot = load_robot(robot_name)
    models = {"own": robot, "widened": widened_ranges(robot, widen_rad)}
    if robot_name != "g1":
        models["g1_legs"] = with_g1_leg_ranges(robot)
    row = {"robot": robot_name, "motion": motion, "widen_rad": widen_rad}
    for variant, model in models.items():
        _, quality, _ = retarget_and_score(human, model)
        row[variant] = {key: quality[key] for key in COLUMNS}
    return row


def widened_ranges(robot: Robot, widen_rad: float) -> Robot:
    """A copy of `robot` whose every joint range is `widen_rad` wider at both ends."""
    model = copy.deepcopy(robot.model)
    for name in robot.config.joint_names:
        joint = model.joint(name).id
        model.jnt_range[joint] += (-widen_rad, widen_rad)
    return dataclasses.replace(robot, model=model)


def with_g1_leg_ranges(robot: Robot) -> Robot:
    """A copy of `robot` whose hip yaw, hip roll and knee ranges are G1's (same side, same joint kind)."""
    g1 = load_robot("g1")
    model = copy.deepcopy(robot.model)
    for name in robot.config.joint_names:
        kind = next((k for k in G1_LEG_KINDS if f"_{k}_" in f"_{name}"), None)
        if kind is None:
            continue
        side = name.split("_")[0]
        model.jnt_range[model.joint(name).id] = g1.model.jnt_range[g1.model.joint(f"{side}_{kind}_joint").id]
    return dataclasses.replace(robot, model=model)


def free_ranges(robot: Robot) -> Robot:
    """A copy of `robot` whose ranges hold nothing back that the bench can free: G1's leg ranges,
    then every range `BUILD_FREE_WIDEN_RAD` wider (hip pitch and ankles too). Its build is the
    robot's. On G1 it is `widened_ranges` by that much."""
    return widened_ranges(with_g1_leg_ranges(robot), BUILD_FREE_WIDEN_RAD)


def range_copies(robot: Robot) -> dict[str, Robot]:
    """The copies of `robot` that may show its ranges explain a miss, by name: `g1_legs`,
    `widened` (by `BUILD_FREE_WIDEN_RAD`) and both at once (`free_ranges`). Each is retargeted on
    its own and takes its own branch through hard motion, so none stands for the others. On G1
    (whose legs are G1's) the three are one copy, `widened`."""
    legs = with_g1_leg_ranges(robot)
    widened = widened_ranges(robot, BUILD_FREE_WIDEN_RAD)
    if np.array_equal(legs.model.jnt_range, robot.model.jnt_range):
        return {"widened": widened}
    return {"g1_legs": legs, "widened": widened, "g1_legs_widened": free_ranges(robot)}


def build_free(robot: Robot) -> Robot:
    """A copy of `robot` without its build: `free_ranges`, and every collision geom but the feet's
    a point at its centre."""
    wider = free_ranges(robot)
    model = wider.model
    feet = {robot.body_ids[body] for body in robot.config.foot_bodies}
    for geom in range(model.ngeom):
        if model.geom_bodyid[geom] not in feet:
            model.geom_type[geom] = mujoco.mjtGeom.mjGEOM_SPHERE
            model.geom_size[geom] = (1e-6, 0.0, 0.0)
    return wider


def _change(row: dict, key: str) -> str:
    return " → ".join(str(row[variant][key]) for variant in VARIANTS if variant in row)


def _table(rows: list[dict], widen_rad: float) -> str:
    header = " → ".join(VARIANTS)
    lines = [
        "| robot | take | " + " | ".join(f"{label}: {header}" for label in COLUMNS.values()) + " |",
        "|" + "---|" * (len(COLUMNS) + 2),
    ]
    for row in rows:
        cells = [" → ".join(_cell(row.get(variant), key) for variant in VARIANTS) for key in COLUMNS]
        lines.append(f"| {row['robot']} | {row['motion']} | " + " | ".join(cells) + " |")
    for robot in sorted({row["robot"] for row in rows}):
        mine = [row for row in rows if row["robot"] == robot]
        totals = [
            str(sum(row[variant]["diverged_frames"] for row in mine)) if variant in mine[0] else "-"
            for variant in VARIANTS
        ]
        lines.append(f"| {robot} | all takes | {' → '.join(totals)} |" + " |" * (len(COLUMNS) - 1))
    lines.append("")
    lines.append(
        f"Each cell: the robot's own model → a copy with G1's {', '.join(G1_LEG_KINDS)} ranges (H1, H1-2; '-' for G1)"
        f" → a copy with every joint range {widen_rad:g} rad wider at both ends."
    )
    lines.append("Pelvis deviation in m, skate in mm/s, keypoint error and penetration in mm.")
    return "\n".join(lines) + "\n"


def _cell(quality: dict | None, key: str) -> str:
    if quality is None:
        return "-"
    value = quality[key]
    if key == "pelvis_height_dev_p95_m":
        return f"{value:.3f}"
    if isinstance(value, float):
        return f"{value:.1f}"
    return str(value)


if __name__ == "__main__":
    main()
