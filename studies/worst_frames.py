"""Benchmark view: the worst frame of each robot's worst take, drawn beside the scaled human.

    python -m studies.worst_frames [--results bench/results/retarget.json] [--out studies/results/worst_frames]

A robot's worst take is the one of `bench/retarget.py`'s table with the largest keypoint error
(the frame farthest from the human); its worst frame is that frame. The take is retargeted again
(the same code and params as the table), and `<out>_<robot>.png` draws the frame from the side
and the front: robot bodies joined to their parents, the human targets they follow, and a line from
each key body to its target. `<out>.json` lists, per robot, the take, the frame and its time,
the keypoint error, the key body farthest off, the pelvis height deviation, the floor penetration
and the joints held at a bound of their range in that frame.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from bench.retarget import retarget_and_score  # noqa: E402
from rd_pipeline import paths  # noqa: E402
from rd_pipeline.motion.bvh import read_bvh  # noqa: E402
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, human_motion_from_bvh  # noqa: E402
from rd_pipeline.retarget.quality import QualityThresholds, quality_series, range_limited  # noqa: E402
from rd_pipeline.robots import load_robot  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("bench/results/retarget.json"))
    parser.add_argument("--out", type=Path, default=Path("studies/results/worst_frames"))
    args = parser.parse_args()
    rows = json.loads(args.results.read_text())
    found = {}
    for robot_name in dict.fromkeys(row["robot"] for row in rows):
        mine = [row for row in rows if row["robot"] == robot_name]
        worst = max(mine, key=lambda row: row["ours"]["keypoint_error_max_mm"])
        picture = args.out.parent / f"{args.out.name}_{robot_name}.png"
        found[robot_name] = _worst_frame(robot_name, worst["motion"], picture)
        print(json.dumps({robot_name: found[robot_name]}), flush=True)
    args.out.with_suffix(".json").write_text(json.dumps(found, indent=2) + "\n")


def _worst_frame(robot_name: str, motion: str, picture: Path) -> dict:
    robot = load_robot(robot_name)
    human = human_motion_from_bvh(read_bvh(paths.bvh_path(motion)), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
    result, _, _ = retarget_and_score(human, robot)
    reference = result.reference
    targets = result.targets
    series = quality_series(robot, reference, targets.positions, targets.bodies, targets.human_pelvis)
    frame = int(series["keypoint_error_m"].argmax())
    key_index = [reference.body_names.index(body) for body in targets.bodies]
    gaps = np.linalg.norm(reference.body_pos_w[frame, key_index] - targets.positions[frame], axis=-1)
    held = range_limited(robot, reference.joint_pos[frame : frame + 1], QualityThresholds())[0]
    figures = {
        "take": motion,
        "frame": frame,
        "time_s": round(frame / reference.fps, 2),
        "keypoint_error_mm": round(1000.0 * float(series["keypoint_error_m"][frame]), 1),
        "farthest_body": targets.bodies[int(gaps.argmax())],
        "farthest_body_gap_mm": round(1000.0 * float(gaps.max()), 1),
        "pelvis_height_dev_m": round(float(series["pelvis_height_dev_m"][frame]), 3),
        "penetration_mm": round(1000.0 * float(series["penetration_m"][frame]), 1),
        "range_held_joints": [name for name, at in zip(robot.config.joint_names, held) if at],
        "picture": picture.name,
    }
    _draw(robot, reference, targets, frame, figures, picture)
    return figures


def _draw(robot, reference, targets, frame: int, figures: dict, picture: Path) -> None:
    """Side (x-z) and front (y-z) views of one frame, centred on the pelvis."""
    model = robot.model
    names = reference.body_names
    points = reference.body_pos_w[frame]
    wanted = targets.positions[frame]
    centre = points[names.index(robot.config.root_body)].copy()
    centre[2] = 0.0
    fig, axes = plt.subplots(1, 2, figsize=(9, 5))
    for ax, (h, label) in zip(axes, ((0, "side: x (m)"), (1, "front: y (m)"))):
        for i, name in enumerate(names):
            parent = model.body(int(model.body_parentid[model.body(name).id])).name
            if parent in names:
                j = names.index(parent)
                ax.plot(
                    [points[i, h] - centre[h], points[j, h] - centre[h]], [points[i, 2], points[j, 2]], "b-", lw=1.5
                )
        for body, target in zip(targets.bodies, wanted):
            at = points[names.index(body)]
            ax.plot([at[h] - centre[h], target[h] - centre[h]], [at[2], target[2]], "r:", lw=1)
        ax.plot(wanted[:, h] - centre[h], wanted[:, 2], "rx", ms=6, label="scaled human target")
        ax.plot(points[:, h] - centre[h], points[:, 2], "bo", ms=3, label="robot body")
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xlabel(label)
        ax.set_ylabel("z (m)")
        ax.set_aspect("equal")
    axes[0].legend(fontsize=7, loc="upper right")
    held = ", ".join(figures["range_held_joints"]) or "none"
    fig.suptitle(
        f"{robot.config.name} {figures['take']} frame {figures['frame']} ({figures['time_s']} s): keypoint error "
        f"{figures['keypoint_error_mm']} mm, {figures['farthest_body']} {figures['farthest_body_gap_mm']} mm off\n"
        f"range-held: {held}",
        fontsize=8,
    )
    fig.tight_layout()
    fig.savefig(picture, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
