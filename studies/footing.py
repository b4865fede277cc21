"""Benchmark: how flat the feet of a reference stand, this project's retarget against the dataset's.

    python -m studies.footing [--robots g1 h1 h1_2] [--motions dance1_subject1 dance1_subject2 dance1_subject3]
        [--tilt-deg 8] [--sparse-support 0.3] [--out studies/results/footing]

For each robot and take with both a BVH file and a dataset CSV, builds the reference both ways (the
`retarget` stage from the BVH, the `import` stage from the LAFAN1_Retargeting_Dataset CSV; `cpu`
profile) and counts, per second (`rd_pipeline.motion.footing`), the seconds whose lowest foot is
tilted more than `--tilt-deg` (median over the second) and the seconds with a planted foot in fewer
than `--sparse-support` of their frames, with the median tilt and planted share over the take. A
policy tracks what its reference asks: a flat-soled robot asked to stand on a tilted sole stands on
its edge. Writes `<out>.json` and `<out>.md`.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path
from typing import Any

from bench.common import write_result
from rd_pipeline.api import workspace
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.footing import Footing, footing_per_second
from rd_pipeline.robots import load_robot

SOURCES = {"bvh": "this project's retarget", "csv": "dataset CSV"}


def main() -> None:
    args = _parser().parse_args()
    try:
        rows = [
            _row(robot, motion, source, args.tilt_deg, args.sparse_support)
            for robot in args.robots
            for motion in args.motions
            for source in SOURCES
        ]
    except (PipelineError, ValueError) as exc:
        sys.exit(f"error: {exc}")
    result = {"tilt_deg": args.tilt_deg, "sparse_support": args.sparse_support, "rows": rows}
    write_result(args.out, result, _table(result))


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", nargs="+", default=["g1", "h1", "h1_2"])
    parser.add_argument("--motions", nargs="+", default=["dance1_subject1", "dance1_subject2", "dance1_subject3"])
    parser.add_argument("--tilt-deg", type=float, default=8.0, help="a second's lowest foot tilted more than this")
    parser.add_argument(
        "--sparse-support", type=float, default=0.3, help="a second's planted share below this counts as unsupported"
    )
    parser.add_argument("--out", type=Path, default=Path("studies/results/footing"))
    return parser


def _row(robot: str, motion: str, source: str, tilt_deg: float, sparse_support: float) -> dict[str, Any]:
    plan = workspace.plan(robot, motion, "cpu", source=source)
    stage = workspace.providing(plan, "reference")
    workspace.run(plan, until=stage, resume=True)
    footing = footing_per_second(workspace.reference(plan), load_robot(robot).config.foot_bodies)
    tilted = [second.start_s for second in footing if second.lowest_foot_tilt_deg > tilt_deg]
    unsupported = [second.start_s for second in footing if second.planted_share < sparse_support]
    return {
        "robot": robot,
        "motion": motion,
        "source": source,
        "seconds": len(footing),
        "tilted_seconds": tilted,
        "unsupported_seconds": unsupported,
        "median_tilt_deg": _median(footing, "lowest_foot_tilt_deg"),
        "median_planted_share": _median(footing, "planted_share"),
    }


def _median(footing: list[Footing], field: str) -> float:
    return round(statistics.median(getattr(second, field) for second in footing), 3)


def _table(result: dict[str, Any]) -> str:
    lines = [
        f"# Footing per second: seconds whose lowest foot is tilted more than {result['tilt_deg']:g} degrees, "
        f"and seconds with a planted foot in under {result['sparse_support']:.0%} of their frames",
        "",
        "| robot | motion | reference | seconds | tilted | unsupported | median tilt (deg) | median planted share |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in result["rows"]:
        lines.append(
            f"| {row['robot']} | {row['motion']} | {SOURCES[row['source']]} | {row['seconds']} | "
            f"{len(row['tilted_seconds'])} | {len(row['unsupported_seconds'])} | {row['median_tilt_deg']:.1f} | "
            f"{row['median_planted_share']:.2f} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
