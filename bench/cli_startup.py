"""Benchmark: wall time of a cached `rd-pipeline run --until parse` (the issue's bar: under 1 s).

    python -m bench.cli_startup [--repeats 7] [--out bench/results/cli_startup.json]

Runs the installed `rd-pipeline` entry point as a user would, in a temporary artifact store whose
parse artifact is computed first; reports the median and every run.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def timed_run(env: dict[str, str]) -> float:
    began = time.perf_counter()
    subprocess.run(
        [Path(sys.executable).parent / "rd-pipeline", "run", "--until", "parse"],
        env=env,
        capture_output=True,
        check=True,
    )
    return time.perf_counter() - began


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--out", type=Path, default=Path("bench/results/cli_startup.json"))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as store:
        env = {**os.environ, "RD_ARTIFACTS": store}
        timed_run(env)  # computes the parse artifact
        seconds = [round(timed_run(env), 3) for _ in range(args.repeats)]
    result = {
        "command": "rd-pipeline run --until parse (cached)",
        "median_s": statistics.median(seconds),
        "runs_s": seconds,
        "cpus": os.cpu_count(),
        "load_1min": os.getloadavg()[0],
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
