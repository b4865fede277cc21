"""Benchmark: deterministic start-zero survival of trained checkpoints against the zero-action policy.

    python -m bench.learning --robot g1 --motion dance1_subject2 --profile cpu --clip 0:10 \
        --checkpoints DIR [--set stage.param=value ...] [--out bench/results/learning.json]

Rebuilds the training environment (robot, reference clip and the profile's settings, resolved by
the same pipeline as `rd-pipeline run`) on nominal physics, and rolls out from frame 0 with the
actor's mean action. DIR may be a finished artifact or the work folder of a run in progress.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

from rd_pipeline.api import workspace
from rd_pipeline.env.mdp.rewards import GROUPS
from rd_pipeline.env.tracking_env import TrackingEnv
from rd_pipeline.errors import PipelineError
from rd_pipeline.robots import load_robot
from rd_pipeline.sampling.sampler import SegmentSampler
from rd_pipeline.training.config import TrainConfig, clip_frames
from rd_pipeline.training.evaluate import checkpoint_scorer, nominal, survival, zero_action
from rd_pipeline.training.log import CHECKPOINT_DIR, checkpoints_by_iteration
from rd_pipeline.training.ppo import build_ppo


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--profile", default="cpu")
    parser.add_argument("--clip", default="0:10")
    parser.add_argument("--checkpoints", type=Path, required=True)
    parser.add_argument(
        "--set", nargs="*", default=[], help="overrides the run used, e.g. train.env.actions.mode=selective"
    )
    parser.add_argument("--out", type=Path, default=Path("bench/results/learning.json"))
    args = parser.parse_args()
    plan = workspace.plan(args.robot, args.motion, args.profile, overrides=(f"train.clip={args.clip}", *args.set))
    params: TrainConfig = plan.stage("train").params
    try:
        reference = workspace.reference(plan)
    except PipelineError as exc:
        sys.exit(f"error: {exc}")
    robot = load_robot(args.robot)
    start, end = clip_frames(params.clip, reference.fps, reference.n_frames)
    reference = reference.frames(start, end)
    starts = np.arange(0, reference.n_frames, 50)
    lengths = np.minimum(50, reference.n_frames - starts)

    def make_env() -> TrackingEnv:
        sampler = SegmentSampler(params.sampler, torch.ones(len(starts)), seed=0)
        return TrackingEnv(robot, reference, sampler, starts, lengths, nominal(params.env, 1), seed=0)

    env = make_env()
    zero = float(survival(env, zero_action(env.num_actions), torch.tensor([0]))[0])
    rows = {"clip_s": reference.n_frames / reference.fps, "zero_action_survival_s": zero, "checkpoints": {}}
    # Either the training folder or its checkpoints folder.
    folder = args.checkpoints if (args.checkpoints / CHECKPOINT_DIR).is_dir() else args.checkpoints.parent
    # Scored as `train` scores them, from frame 0 alone: the environment starts over for each.
    env = make_env()
    ppo = build_ppo(env.get_observations(), 1, env.num_actions, len(GROUPS), params.ppo)
    ppo.eval_mode()
    score = checkpoint_scorer(env, lambda obs: ppo.actor(obs, stochastic_output=False))
    for path in checkpoints_by_iteration(folder).values():
        ppo.load(torch.load(path, weights_only=False)["algorithm"], None, strict=True)
        rows["checkpoints"][path.stem] = score()["start_zero_s"]
        print(path.stem, rows["checkpoints"][path.stem], flush=True)
    best = max(rows["checkpoints"].values())
    rows["best_policy_survival_s"] = best
    rows["ratio_best_to_zero_action"] = round(best / zero, 3)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(rows, indent=2) + "\n")
    print(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
