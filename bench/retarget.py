"""Benchmark: our retargeting against the LAFAN1_Retargeting_Dataset CSVs, same clips, same ruler.

    python bench/retarget.py [--robots g1 h1 h1_2] [--motions dance1_subject1 ...] [--out bench/results/retarget]

For each (robot, clip): retarget the BVH with the stage's default params on one core (speed is
output frames per second of the whole retargeting), import the dataset CSV at 50 Hz, and compute
`retarget_quality` for both. Writes `<out>.json` and a markdown table `<out>.md`.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from rd_pipeline import paths
from rd_pipeline.evaluation.retarget_quality import retarget_quality
from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, human_motion_from_bvh
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.retarget.retarget import retarget
from rd_pipeline.robots import load_robot
from stages.import_motion import ImportParams
from stages.retarget import RetargetParams

COLUMNS = [
    "fps_frames_per_s", "penetration_max_mm", "penetration_p95_mm", "skate_stance_mean_mm_s",
    "joint_limit_violations", "velocity_limit_violations", "self_collision_frames", "jerk_mean",
    "keypoint_error_mean_mm",
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=["g1", "h1", "h1_2"])
    parser.add_argument("--motions", nargs="+", default=["dance1_subject1", "dance1_subject2", "dance1_subject3"])
    parser.add_argument("--out", type=Path, default=Path("bench/results/retarget"))
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    params, import_params = RetargetParams(), ImportParams()
    rows = []
    for motion in args.motions:
        human = human_motion_from_bvh(read_bvh(paths.bvh_path(motion)), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
        for name in args.robots:
            robot = load_robot(name)
            began = time.perf_counter()
            result = retarget(human, robot, params.fps, params.contact, params.shape, params.body_contact, params.weights, params.ik)
            seconds = time.perf_counter() - began
            ours = retarget_quality(
                robot, result.reference, keypoint_targets=result.targets.positions,
                keypoint_bodies=result.targets.bodies, frames_per_s=result.reference.n_frames / seconds,
            )
            dataset = import_retargeted_csv(
                paths.csv_path(name, motion), robot, import_params.source_fps, import_params.fps,
                import_params.interpolation, import_params.contact,
            ).reference
            # The dataset is scored against our scaled-human targets too, after the heading and
            # offset that best align its (arbitrary) world frame with ours.
            theirs = retarget_quality(
                robot, dataset, keypoint_targets=_aligned_targets(dataset, result.targets),
                keypoint_bodies=result.targets.bodies,
            )
            rows.append({"robot": name, "motion": motion, "seconds": round(seconds, 2), "ours": ours, "dataset": theirs})
            print(json.dumps(rows[-1]), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(rows, indent=2) + "\n")
    args.out.with_suffix(".md").write_text(_table(rows))
    print(_table(rows))


def _aligned_targets(reference, targets) -> np.ndarray:
    """Our targets moved by the yaw + translation that best fits the reference's key bodies (2-D Procrustes)."""
    index = [reference.body_names.index(b) for b in targets.bodies]
    theirs = reference.body_pos_w[:, index].reshape(-1, 3)
    ours = targets.positions.reshape(-1, 3)
    a, b = ours[:, :2] - ours[:, :2].mean(0), theirs[:, :2] - theirs[:, :2].mean(0)
    u, _, vt = np.linalg.svd(a.T @ b)
    rotation = (u @ vt).T
    if np.linalg.det(rotation) < 0:
        u[:, -1] *= -1
        rotation = (u @ vt).T
    moved = targets.positions.copy()
    moved[..., :2] = (targets.positions[..., :2] - ours[:, :2].mean(0)) @ rotation.T + theirs[:, :2].mean(0)
    moved[..., 2] += theirs[:, 2].mean() - ours[:, 2].mean()
    return moved


def _table(rows: list[dict]) -> str:
    short = ["fps", "pen max", "pen p95", "skate", "jl viol", "vel viol", "self-coll", "jerk", "kp err"]
    lines = ["| robot | motion | source | " + " | ".join(short) + " |", "|" + "---|" * (len(short) + 3)]
    for row in rows:
        for source in ("ours", "dataset"):
            values = [row[source][c] for c in COLUMNS]
            cells = ["-" if v is None else f"{v:.1f}" if isinstance(v, float) else str(v) for v in values]
            lines.append(f"| {row['robot']} | {row['motion']} | {source} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
