"""Benchmark: one inference step of an exported policy at batch 1 on one core, TorchScript
(`policy.pt`) and ONNX on onnxruntime (`policy.onnx`) side by side.

    python -m bench.export --policy artifacts/export/g1/dance1_subject2/<key> [--out bench/results/export.json]

The two runtimes alternate in blocks of 100 calls (2000 timed calls each after 200 warm-up calls),
so both see the same machine load. Reports the median and 99th percentile of each and their
ratio (bar: 1 ms).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from rd_pipeline.policy_runtime import OnnxPolicy
from rd_pipeline.policy_spec import ONNX_FILE, POLICY_FILE, SPEC_FILE, load_policy_spec

BLOCK = 100
"""Calls of one runtime before switching to the other."""


def time_calls(call: Callable[[], object], count: int) -> list[float]:
    times = []
    for _ in range(count):
        began = time.perf_counter()
        call()
        times.append(time.perf_counter() - began)
    return times


def summary(times: list[float]) -> dict[str, float]:
    ordered = sorted(times)
    return {
        "median_ms": round(1000 * statistics.median(ordered), 4),
        "p99_ms": round(1000 * ordered[int(0.99 * len(ordered))], 4),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", type=Path, required=True, help="an export artifact folder")
    parser.add_argument("--out", type=Path, default=Path("bench/results/export.json"))
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    torch.set_num_threads(1)
    spec = load_policy_spec(args.policy / SPEC_FILE)
    scripted = torch.jit.load(str(args.policy / POLICY_FILE))
    onnx_policy = OnnxPolicy(args.policy / ONNX_FILE)
    obs = np.random.default_rng(0).normal(size=(1, spec.get("observation.size"))).astype(np.float32)
    obs_torch = torch.from_numpy(obs)
    calls = {"torchscript": lambda: scripted(obs_torch), "onnx": lambda: onnx_policy(obs)}
    times: dict[str, list[float]] = {name: [] for name in calls}
    with torch.inference_mode():
        for call in calls.values():
            time_calls(call, 200)
        for _ in range(2000 // BLOCK):
            for name, call in calls.items():
                times[name] += time_calls(call, BLOCK)
    result = {
        "policy": args.policy.name,
        "robot": spec.get("robot"),
        "observation_size": spec.get("observation.size"),
        "actions": len(spec.get("action.outputs")),
        "threads": 1,
        "calls": len(times["torchscript"]),
        **{name: summary(values) for name, values in times.items()},
        "onnx_over_torchscript_median": round(
            statistics.median(times["onnx"]) / statistics.median(times["torchscript"]), 3
        ),
        "bar_ms": 1.0,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
