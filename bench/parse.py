"""Benchmark: BVH parse + forward kinematics of a LAFAN1 dance on one core, and a CLI cache hit.

    python -m bench.parse [--repeats 15] [--out bench/results/parse.json]

Reports medians. The issue's bar: parse + FK of the 3945-frame dance in at most 0.5 s; a cache hit
of `rd-pipeline run --until parse` in under 2 s.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core, as the issue asks
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from rd_pipeline import paths
from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, human_motion_from_bvh


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--out", type=Path, default=Path("bench/results/parse.json"))
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})

    path = paths.bvh_path(args.motion)
    parse_s, fk_s, total_s = [], [], []
    for _ in range(args.repeats):
        began = time.perf_counter()
        clip = read_bvh(path)
        parsed = time.perf_counter()
        human_motion_from_bvh(clip, LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
        done = time.perf_counter()
        parse_s.append(parsed - began)
        fk_s.append(done - parsed)
        total_s.append(done - began)

    with tempfile.TemporaryDirectory() as store:
        env = {**os.environ, "RD_ARTIFACTS": store}
        command = [sys.executable, "-m", "rd_pipeline", "run", "--motion", args.motion, "--until", "parse"]
        subprocess.run(command, env=env, check=True, capture_output=True)
        hits = []
        for _ in range(5):
            began = time.perf_counter()
            subprocess.run(command, env=env, check=True, capture_output=True)
            hits.append(time.perf_counter() - began)

    result = {
        "motion": args.motion,
        "frames": clip.channels.shape[0],
        "repeats": args.repeats,
        "parse_median_s": round(statistics.median(parse_s), 4),
        "fk_median_s": round(statistics.median(fk_s), 4),
        "parse_fk_median_s": round(statistics.median(total_s), 4),
        "parse_fk_target_s": 0.5,
        "cache_hit_cli_median_s": round(statistics.median(hits), 3),
        "cache_hit_target_s": 2.0,
        "machine": f"{platform.machine()} {platform.processor() or ''} python {platform.python_version()}".strip(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
