"""Benchmark: a fingerprint of what the pipeline computes, to show a refactor changed nothing.

    python -m bench.behaviour keys  [--out bench/results/behaviour_keys.json]
    python -m bench.behaviour train [--out bench/results/behaviour_train.json] [--iterations 20]

`keys`: the planned artifact key of every stage for every (robot, take) the data folders hold,
under each profile (seed 0). Keys hash the stage, its version, its resolved params, upstream keys
and input files, so equal keys mean the same params reach every stage.

`train`: G1 dance1_subject2 0-10 s on the `cpu` profile for the first `--iterations` iterations
(a checkpoint every half of them), then export and validate. It writes the training log without
its timings, a sha256 of every tensor in each checkpoint (weights, optimizer, sampler, environment
and RNG state) and the numbers of the validation report. Run it before and after a change into two
files and compare them.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import tempfile
from pathlib import Path
from typing import Any

import torch

from rd_pipeline.api import workspace
from rd_pipeline.errors import PipelineError
from rd_pipeline.profiles import PROFILES
from rd_pipeline.robots.config import available_robots

TIMINGS = ("seconds", "samples_per_s")
"""Training-log fields that measure the machine, not the computation."""


def planned_keys() -> dict[str, dict[str, str]]:
    """`<profile>/<robot>/<motion>` -> stage -> key, for every pair the data folders can run."""
    found: dict[str, dict[str, str]] = {}
    for profile in PROFILES:
        for robot in available_robots():
            for motion in workspace.available_motions():
                try:
                    plan = workspace.plan(robot, motion, profile=profile)
                except PipelineError:
                    continue  # no source of this motion for this robot
                found[f"{profile}/{robot}/{motion}"] = {stage.name: stage.key for stage in plan.stages()}
    return found


def tensor_digest(value: Any) -> Any:
    """The same nesting with every tensor or array replaced by the sha256 of its bytes."""
    if isinstance(value, torch.Tensor):
        return hashlib.sha256(value.detach().cpu().contiguous().numpy().tobytes()).hexdigest()[:16]
    if isinstance(value, dict):
        return {str(k): tensor_digest(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [tensor_digest(v) for v in value]
    if hasattr(value, "tobytes"):
        return hashlib.sha256(value.tobytes()).hexdigest()[:16]
    return value


def training_fingerprint(iterations: int, store: Path) -> dict[str, Any]:
    overrides = (
        "train.clip=0:10",
        f"train.iterations={iterations}",
        f"train.checkpoint_every={max(1, iterations // 2)}",
    )
    plan = workspace.plan("g1", "dance1_subject2", profile="cpu", overrides=overrides, store=store)
    workspace.run(plan)
    train = workspace.artifact(plan, "train")
    rows = [{k: v for k, v in row.items() if k not in TIMINGS} for row in workspace.training_log(train)]
    checkpoints = {
        path.stem: tensor_digest(torch.load(path, weights_only=False))
        for path in workspace.training_checkpoints(train).values()
    }
    report = json.loads((workspace.artifact(plan, "validate") / "report.json").read_text())
    return {
        "keys": {stage.name: stage.key for stage in plan.stages()},
        "training_log": rows,
        "checkpoints": checkpoints,
        "validation": report,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("keys", "train"))
    parser.add_argument("--iterations", type=int, default=20)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    out = args.out or Path(f"bench/results/behaviour_{args.what}.json")
    if args.what == "keys":
        result: dict[str, Any] = planned_keys()
    else:
        with tempfile.TemporaryDirectory() as store:
            result = training_fingerprint(args.iterations, Path(store))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
