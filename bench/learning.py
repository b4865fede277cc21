"""Benchmark: deterministic start-zero survival of trained checkpoints against the zero-action policy.

    python bench/learning.py --train-dir ARTIFACT_DIR [--out bench/results/learning.json]

Rebuilds the training environment (same robot, reference clip and settings, from the artifact's
manifest) on nominal physics and rolls out from frame 0 with the actor's mean action.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from rd_pipeline.artifacts.stage import _override
from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
from rd_pipeline.paths import artifacts_dir
from rd_pipeline.rl.env import TrackingEnv
from rd_pipeline.rl.evaluate import nominal, survival, zero_action
from rd_pipeline.rl.ppo import build_ppo
from rd_pipeline.rl.rewards import GROUPS
from rd_pipeline.robots import load_robot
from rd_pipeline.sampling.sampler import SegmentSampler
from stages.train import TrainParams, _slice, clip_frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train-dir", type=Path, required=True)
    parser.add_argument("--out", type=Path, default=Path("bench/results/learning.json"))
    args = parser.parse_args()
    manifest = json.loads((args.train_dir / "manifest.json").read_text())
    params: TrainParams = _override(TrainParams(), _flatten_tuples(manifest["params"]), "train")
    robot = load_robot(manifest["robot"])
    reference_key = None
    for stage in ("retarget", "import"):
        if stage in manifest["upstream"]:
            reference_key = (stage, manifest["upstream"][stage])
    reference = ReferenceMotion.load(
        artifacts_dir() / reference_key[0] / manifest["robot"] / manifest["motion"] / reference_key[1] / REFERENCE_FILE
    )
    start, end = clip_frames(params.clip, reference.fps, reference.n_frames)
    reference = _slice(reference, start, end)
    starts = np.arange(0, reference.n_frames, 50)
    lengths = np.minimum(50, reference.n_frames - starts)

    def make_env() -> TrackingEnv:
        sampler = SegmentSampler(params.sampler, torch.ones(len(starts)), seed=0)
        return TrackingEnv(robot, reference, sampler, starts, lengths, nominal(params.env, 1), seed=0)

    env = make_env()
    zero = float(survival(env, zero_action(env.num_actions), torch.tensor([0]))[0])
    rows = {"clip_s": reference.n_frames / 50.0, "zero_action_survival_s": zero, "checkpoints": {}}
    for path in sorted((args.train_dir / "checkpoints").glob("model_*.pt"), key=lambda p: int(p.stem.split("_")[1])):
        env = make_env()
        ppo = build_ppo(env.get_observations(), 1, env.num_actions, len(GROUPS), params.ppo)
        ppo.load(torch.load(path, weights_only=False)["algorithm"], None, strict=True)
        ppo.eval_mode()
        mean_action = lambda obs: ppo.actor(obs, stochastic_output=False)  # noqa: E731
        rows["checkpoints"][path.stem] = float(survival(env, mean_action, torch.tensor([0]))[0])
        print(path.stem, rows["checkpoints"][path.stem], flush=True)
    best = max(rows["checkpoints"].values())
    rows["best_policy_survival_s"] = best
    rows["ratio_best_to_zero_action"] = round(best / zero, 3)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(rows, indent=2) + "\n")
    print(json.dumps(rows, indent=2))


def _flatten_tuples(values: dict) -> dict:
    return {k: _flatten_tuples(v) if isinstance(v, dict) else v for k, v in values.items()}


if __name__ == "__main__":
    main()
