"""Benchmark: our retargeting on every shared LAFAN1 take and robot, beside the dataset CSVs, one ruler.

    python -m bench.retarget [--robots g1 g1_29dof h1 h1_2] [--motions dance1_subject1 ...] [--jobs 2] [--resume]
                             [--tempo 1.0] [--out bench/results/retarget]

For each (robot, take): retarget the BVH with the stage's default params, one take per core
(speed is output frames per second of the whole retargeting), and score it with
`retarget_quality` against the scaled human. Where the LAFAN1_Retargeting_Dataset has the take,
its CSV is imported at 50 Hz and scored the same way. Each finished row is appended to
`<out>.jsonl` at once (`--resume` skips rows already there); `<out>.json` and a markdown table
`<out>.md` with the issue's bars are written at the end.

`--tempo` plays every take that many times faster (the BVH's frame rate scaled), a stand-in for
the faster takes of LAFAN1 that are not in the shared folder (runs, sprints, fights); the dataset
CSVs, recorded at the takes' own pace, are then left out.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from bench.common import write_result
from rd_pipeline import paths
from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, HumanMotion, human_motion_from_bvh
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.quality import retarget_quality
from rd_pipeline.retarget.retarget import RetargetResult, retarget
from rd_pipeline.robots import Robot, load_robot
from rd_pipeline.stages.import_motion import ImportConfig


def shared_takes() -> list[str]:
    """Every BVH take in `RD_LAFAN_DIR`, dances first: whatever the data folder holds today."""
    names = [path.stem for path in paths.lafan_dir().glob("*.bvh")]
    return sorted(names, key=lambda name: (not name.startswith("dance"), name))


COLUMNS = {
    "fps_frames_per_s": "fps",
    "penetration_max_mm": "pen max",
    "penetration_p95_mm": "pen p95",
    "pelvis_height_dev_p95_m": "pelvis dev p95",
    "skate_stance_mean_mm_s": "skate",
    "joint_limit_violations": "jl",
    "range_limited_frames": "range-held",
    "range_limited_joints": "most held joint",
    "velocity_limit_violations": "vel",
    "self_collision_frames": "self-coll",
    "jerk_mean": "jerk",
    "keypoint_error_mean_mm": "kp mean",
    "keypoint_error_p95_mm": "kp p95",
    "keypoint_error_max_mm": "kp max",
    "diverged_frames": "diverged",
    "root_speed_p999_m_s": "root p99.9",
    "human_root_speed_p999_m_s": "human p99.9",
    "pelvis_off_target_pct": "pelvis >0.2 m off %",
    "planted_foot_turn_p95_deg": "planted foot turn p95",
}
BARS = {
    "penetration_max_mm": 10.0,
    "pelvis_height_dev_p95_m": 0.10,
    "skate_stance_mean_mm_s": 20.0,
    "joint_limit_violations": 0,
    "velocity_limit_violations": 0,
    "self_collision_frames": 0,
    "diverged_frames": 0,
}
"""The issue's bars, each an upper bound."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=["g1", "g1_29dof", "h1", "h1_2"])
    parser.add_argument("--motions", nargs="+", default=shared_takes())
    parser.add_argument("--jobs", type=int, default=2, help="takes retargeted at once, each pinned to its own core")
    parser.add_argument("--resume", action="store_true", help="keep the rows already in <out>.jsonl")
    parser.add_argument("--tempo", type=float, default=1.0, help="play every take this many times faster")
    parser.add_argument("--out", type=Path, default=Path("bench/results/retarget"))
    args = parser.parse_args()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    log = args.out.with_suffix(".jsonl")
    rows = resume_log(log, args.resume)
    todo = pending(rows, args.motions, args.robots)
    cores = multiprocessing.Manager().Queue()
    for core in sorted(os.sched_getaffinity(0))[: args.jobs]:
        cores.put(core)
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(_measure, robot, motion, args.tempo, cores) for robot, motion in todo]
        for future in as_completed(futures):
            row = future.result()
            rows.append(row)
            with log.open("a") as file:
                file.write(json.dumps(row) + "\n")
            label = f"{row['robot']:<5} {row['motion']:<26} {row['seconds']:7.1f} s"
            print(f"{label}  {_verdict(row['ours'])}", flush=True)
    rows = in_take_order(rows, args.motions, args.robots)
    write_result(args.out, rows, _table(rows))


def resume_log(log: Path, resume: bool) -> list[dict]:
    """The rows already in a bench's `.jsonl` log when resuming; otherwise the log starts empty."""
    if resume and log.exists():
        return [json.loads(line) for line in log.read_text().splitlines()]
    log.write_text("")
    return []


def pending(rows: list[dict], motions: list[str], robots: list[str]) -> list[tuple[str, str]]:
    """The (robot, take) pairs `rows` does not have yet, take by take."""
    done = {(row["robot"], row["motion"]) for row in rows}
    return [(robot, motion) for motion in motions for robot in robots if (robot, motion) not in done]


def in_take_order(rows: list[dict], motions: list[str], robots: list[str]) -> list[dict]:
    """`rows` take by take, robots in the order asked; rows of other takes or robots last."""
    order = {(robot, motion): i for i, (motion, robot) in enumerate((m, r) for m in motions for r in robots)}
    return sorted(rows, key=lambda row: order.get((row["robot"], row["motion"]), len(order)))


def _measure(robot_name: str, motion: str, tempo: float, cores) -> dict:
    core = cores.get()
    try:
        os.sched_setaffinity(0, {core})
        return _retarget_and_score(robot_name, motion, tempo)
    finally:
        cores.put(core)


def _retarget_and_score(robot_name: str, motion: str, tempo: float = 1.0) -> dict:
    import_params = ImportConfig()
    human = human_motion_from_bvh(read_bvh(paths.bvh_path(motion)), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
    human = dataclasses.replace(human, fps=human.fps * tempo)
    robot = load_robot(robot_name)
    result, ours, seconds = retarget_and_score(human, robot)
    targets = result.targets
    row = {"robot": robot_name, "motion": motion, "seconds": round(seconds, 2), "ours": ours, "dataset": None}
    if tempo != 1.0:
        row["tempo"] = tempo
        return row
    csv = paths.csv_path(robot_name, motion)
    if csv is not None and csv.exists():
        dataset = import_retargeted_csv(
            csv,
            robot,
            import_params.source_fps,
            import_params.fps,
            import_params.interpolation,
            import_params.contact,
        ).reference
        n_frames = min(dataset.n_frames, targets.n_frames)
        dataset = dataset.frames(0, n_frames)
        # The dataset is scored against our scaled-human targets, after the heading and offset that
        # best align its (arbitrary) world frame with ours.
        aligned = _aligned(dataset, targets.positions[:n_frames], targets.bodies)
        pelvis = aligned(targets.human_pelvis[:n_frames, None])[:, 0]
        row["dataset"] = retarget_quality(
            robot,
            dataset,
            keypoint_targets=aligned(targets.positions[:n_frames]),
            keypoint_bodies=targets.bodies,
            human_pelvis=pelvis,
        )
    return row


def retarget_and_score(
    human: HumanMotion, robot: Robot, params: RetargetConfig | None = None
) -> tuple[RetargetResult, dict, float]:
    """Retarget `human` onto `robot`, timed, and score it against the scaled human: the result, the
    quality report (with throughput and the pelvis-off-target share) and the seconds it took."""
    began = time.perf_counter()
    result = retarget(human, robot, params or RetargetConfig())
    seconds = time.perf_counter() - began
    targets = result.targets
    quality = retarget_quality(
        robot,
        result.reference,
        keypoint_targets=targets.positions,
        keypoint_bodies=targets.bodies,
        frames_per_s=result.reference.n_frames / seconds,
        human_pelvis=targets.human_pelvis,
        foot_orientations=targets.foot_orientations(robot.config.foot_bodies),
    )
    root = targets.bodies.index(robot.config.root_body)
    off_target = np.linalg.norm(
        result.reference.body_pos_w[:, result.reference.body_names.index(robot.config.root_body)]
        - targets.positions[:, root],
        axis=1,
    )
    quality["pelvis_off_target_pct"] = round(100.0 * float(np.mean(off_target > 0.2)), 2)
    return result, quality, seconds


def _aligned(reference, positions: np.ndarray, bodies):
    """The yaw + translation that best fits our targets onto the reference's key bodies (2-D Procrustes)."""
    index = [reference.body_names.index(b) for b in bodies]
    theirs = reference.body_pos_w[:, index].reshape(-1, 3)
    ours = positions.reshape(-1, 3)
    centred_ours = ours[:, :2] - ours[:, :2].mean(0)
    centred_theirs = theirs[:, :2] - theirs[:, :2].mean(0)
    u, _, vt = np.linalg.svd(centred_ours.T @ centred_theirs)
    if np.linalg.det(u @ vt) < 0:
        u[:, -1] *= -1
    rotation = (u @ vt).T
    shift_xy = theirs[:, :2].mean(0)
    shift_z = theirs[:, 2].mean() - ours[:, 2].mean()
    centre = ours[:, :2].mean(0)

    def move(points: np.ndarray) -> np.ndarray:
        moved = points.copy()
        moved[..., :2] = (points[..., :2] - centre) @ rotation.T + shift_xy
        moved[..., 2] += shift_z
        return moved

    return move


def _verdict(quality: dict) -> str:
    failed = [
        f"{COLUMNS[key]}={quality[key]}" for key, bar in BARS.items() if quality[key] is not None and quality[key] > bar
    ]
    return "meets every bar" if not failed else "over: " + ", ".join(failed)


def _table(rows: list[dict]) -> str:
    lines = [
        "| robot | take | source | s | " + " | ".join(COLUMNS.values()) + " |",
        "|" + "---|" * (len(COLUMNS) + 4),
    ]
    for row in rows:
        for source in ("ours", "dataset"):
            quality = row[source]
            if quality is None:
                continue
            cells = [_cell(quality.get(key), key) for key in COLUMNS]
            seconds = f"{row['seconds']:.1f}" if source == "ours" else "-"
            lines.append(f"| {row['robot']} | {row['motion']} | {source} | {seconds} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append("Bold: over the issue's bar (penetration 10 mm, pelvis deviation 0.10 m, skate 20 mm/s, zero limit,")
    lines.append("self-collision and diverged frames). Errors in mm, speeds in m/s, jerk in rad/s^3, fps on one core;")
    lines.append("'pelvis >0.2 m off %' is the share of frames whose pelvis is more than 0.2 m from its own target;")
    lines.append("'planted foot turn p95' (degrees) how far planted feet are turned from their targets (ours only);")
    lines.append("'range-held': frames where some joint sits at a bound of its range, so the range decided it.")
    return "\n".join(lines) + "\n"


def _cell(value, key: str) -> str:
    if value is None:
        return "-"
    if isinstance(value, dict):  # frames per joint, most first: the first one
        return next((f"{name} {frames}" for name, frames in value.items()), "-")
    if key == "pelvis_height_dev_p95_m":
        text = f"{value:.3f}"
    elif isinstance(value, float):
        text = f"{value:.1f}"
    else:
        text = str(value)
    return f"**{text}**" if key in BARS and value > BARS[key] else text


if __name__ == "__main__":
    main()
