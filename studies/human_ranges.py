"""Benchmark: how far the performers' hips bend, per shared take, the evidence for `retarget_range`.

    python -m studies.human_ranges [--motions dance1_subject1 ...] [--out studies/results/human_ranges]

The thigh (hip to knee) is measured in a pelvis frame built from the skeleton's own positions:
left from the right hip to the left, up from the Hips joint to the Spine joint (made square to
left), forward their cross product. Extension is the thigh's angle behind the pelvis's down axis
in the sagittal plane, flexion the angle in front of it; both in degrees, per leg, as the p99.9
and the maximum over the take. The pelvis frame leans back with the skeleton's lower spine, so
standing reads 10-27 degrees of extension (the first second of dance1_subject2 and
pushAndFall1_subject1): the figures overstate the hip's own extension, which is the safe side for a
bound. Writes `<out>.json` and a markdown table `<out>.md`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from bench.common import write_result
from rd_pipeline import paths
from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, HumanMotion, human_motion_from_bvh

SIDES = ("Left", "Right")


def _unit(vectors: np.ndarray) -> np.ndarray:
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


def hip_extension_deg(human: HumanMotion, side: str) -> np.ndarray:
    """(T,) the thigh's angle behind the pelvis's down axis, in the sagittal plane (negative: flexion)."""
    position = {name: human.pos_w[:, k] for k, name in enumerate(human.names)}
    left = _unit(position["LeftUpLeg"] - position["RightUpLeg"])
    up = position["Spine"] - position["Hips"]
    up = _unit(up - left * np.sum(up * left, axis=-1, keepdims=True))
    forward = np.cross(left, up)
    thigh = position[f"{side}Leg"] - position[f"{side}UpLeg"]
    behind = -np.sum(thigh * forward, axis=-1)
    down = -np.sum(thigh * up, axis=-1)
    return np.degrees(np.arctan2(behind, down))


def measure(motion: str) -> dict:
    human = human_motion_from_bvh(read_bvh(paths.bvh_path(motion)), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
    row: dict = {"motion": motion}
    for side in SIDES:
        extension = hip_extension_deg(human, side)
        row[side.lower()] = {
            "extension_p999_deg": round(float(np.quantile(extension, 0.999)), 1),
            "extension_max_deg": round(float(extension.max()), 1),
            "flexion_max_deg": round(float(-extension.min()), 1),
        }
    return row


def _table(rows: list[dict]) -> str:
    lines = [
        "| take | left ext p99.9 | left ext max | left flex max | right ext p99.9 | right ext max | right flex max |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        cells = [row["motion"]]
        for side in ("left", "right"):
            leg = row[side]
            cells += [str(leg["extension_p999_deg"]), str(leg["extension_max_deg"]), str(leg["flexion_max_deg"])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    takes = sorted(path.stem for path in paths.lafan_dir().glob("*.bvh"))
    parser.add_argument("--motions", nargs="+", default=takes)
    parser.add_argument("--out", type=Path, default=Path("studies/results/human_ranges"))
    args = parser.parse_args()
    rows = [measure(motion) for motion in args.motions]
    largest = max(row[side]["extension_max_deg"] for row in rows for side in ("left", "right"))
    summary = {"hip_extension_max_deg": largest, "takes": rows}
    header = f"Hip extension and flexion of the performers, degrees; largest extension {largest}.\n\n"
    write_result(args.out, summary, header + _table(rows))


if __name__ == "__main__":
    main()
