"""Benchmark: one inference step of an exported `policy.pt` at batch 1 on one core.

    python bench/export.py --policy artifacts/export/g1/dance1_subject2/<key> [--out bench/results/export.json]

Reports the median and 99th percentile over 2000 calls after 200 warm-up calls (bar: 1 ms).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import torch

from rd_pipeline.export.policy_spec import POLICY_FILE, SPEC_FILE, load_policy_spec


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", type=Path, required=True, help="an export artifact folder")
    parser.add_argument("--out", type=Path, default=Path("bench/results/export.json"))
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    torch.set_num_threads(1)
    spec = load_policy_spec(args.policy / SPEC_FILE)
    policy = torch.jit.load(str(args.policy / POLICY_FILE))
    obs = torch.randn(1, spec.get("observation.size"))
    times = []
    with torch.inference_mode():
        for i in range(2200):
            began = time.perf_counter()
            policy(obs)
            if i >= 200:
                times.append(time.perf_counter() - began)
    times.sort()
    result = {
        "robot": spec.get("robot"),
        "observation_size": spec.get("observation.size"),
        "actions": len(spec.get("action.outputs")),
        "threads": 1,
        "calls": len(times),
        "median_ms": round(1000 * statistics.median(times), 4),
        "p99_ms": round(1000 * times[int(0.99 * len(times))], 4),
        "bar_ms": 1.0,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
