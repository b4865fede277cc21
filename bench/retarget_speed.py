"""Benchmark: retarget speed of two checkouts side by side, alone on one core, takes interleaved.

    python -m bench.retarget_speed --trees /path/to/baseline . [--robot g1] [--motions ...] [--rounds 2]
                                   [--core 0] [--out bench/results/retarget_speed]

On a shared machine the speed of one take moves by 10 % or more between runs minutes apart, so
two versions measured in separate runs can differ by more than the change between them. Here each
round retargets every take once with each tree in turn (a fresh process per take, pinned to
`--core`, the tree first on `PYTHONPATH`), and the figures are per-take medians over the rounds
and their ratio. Only the retargeting is timed, as in `bench/retarget.py`. Writes `<out>.json`
and `<out>.md`.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

from bench.common import write_result
from bench.retarget import shared_takes

ONE_TAKE = """
import sys, time
from rd_pipeline import paths
from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, human_motion_from_bvh
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.retarget import retarget
from rd_pipeline.robots import load_robot
human = human_motion_from_bvh(read_bvh(paths.bvh_path(sys.argv[2])), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
robot = load_robot(sys.argv[1])
began = time.perf_counter()
result = retarget(human, robot, RetargetConfig())
print(result.reference.n_frames / (time.perf_counter() - began))
"""
"""Run in a fresh interpreter: which `rd_pipeline` it imports is the tree's, by `PYTHONPATH`."""


def main() -> None:
    args = _parser().parse_args()
    trees = [tree.resolve() for tree in args.trees]
    motions = args.motions or shared_takes()
    fps: dict[str, list[list[float]]] = {motion: [[] for _ in trees] for motion in motions}
    for round_index in range(args.rounds):
        for motion in motions:
            for k, tree in enumerate(trees):
                fps[motion][k].append(_frames_per_s(tree, args.robot, motion, args.core))
            print(f"round {round_index + 1} {motion}: " + " / ".join(f"{v[-1]:.1f}" for v in fps[motion]), flush=True)
    rows = [_row(motion, per_tree) for motion, per_tree in fps.items()]
    result = {"robot": args.robot, "trees": [str(tree) for tree in trees], "rounds": args.rounds, "takes": rows}
    write_result(args.out, result, _table(result))


def _frames_per_s(tree: Path, robot: str, motion: str, core: int) -> float:
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    command = ["taskset", "-c", str(core), sys.executable, "-c", ONE_TAKE, robot, motion]
    done = subprocess.run(command, env=env, cwd=tree, capture_output=True, text=True, check=True)
    return float(done.stdout.strip().splitlines()[-1])


def _row(motion: str, per_tree: list[list[float]]) -> dict:
    medians = [statistics.median(values) for values in per_tree]
    return {
        "motion": motion,
        "fps": [[round(v, 1) for v in values] for values in per_tree],
        "median_fps": [round(m, 1) for m in medians],
        "ratio_last_to_first": round(medians[-1] / medians[0], 3),
    }


def _table(result: dict) -> str:
    names = [Path(tree).name for tree in result["trees"]]
    lines = [
        f"| take | {' | '.join(f'{name} median fps' for name in names)} | ratio | runs |",
        "|---|" + "---|" * (len(names) + 2),
    ]
    for row in result["takes"]:
        medians = " | ".join(f"{m:.1f}" for m in row["median_fps"])
        runs = "; ".join(", ".join(f"{v:.0f}" for v in values) for values in row["fps"])
        lines.append(f"| {row['motion']} | {medians} | {row['ratio_last_to_first']:.3f} | {runs} |")
    ratios = [row["ratio_last_to_first"] for row in result["takes"]]
    lines.append(f"\nMedian ratio {statistics.median(ratios):.3f} ({min(ratios):.3f} to {max(ratios):.3f}).")
    for k, name in enumerate(names):
        at_bar = sum(row["median_fps"][k] >= 300.0 for row in result["takes"])
        lines.append(f"{name}: {at_bar} of {len(ratios)} takes at 300 frames/s or more.")
    return "\n".join(lines) + "\n"


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trees", type=Path, nargs=2, required=True, help="baseline checkout, then the one measured")
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--motions", nargs="*", default=None)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--core", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("bench/results/retarget_speed"))
    return parser


if __name__ == "__main__":
    main()
