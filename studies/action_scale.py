"""Benchmark: from which starts a trained policy helps, as survival with its outputs scaled.

    python -m studies.action_scale --robot h1_2 --motion dance2_subject4 --clip 107:117 --iterations 16000
        [--checkpoint 11400] [--set ...] [--scales 1 0.5 0.25 0] [--starts 10] [--out studies/results/action_scale_h1_2]
        [--joints '*_shoulder_*' '*_elbow_joint'] [--noise-draws 8] [--commit SHA]

Loads a checkpoint of the finished `train` artifact of that plan (its last one by default) and
rolls out its mean outputs, multiplied by each scale, from `--starts` evenly spaced frames on the
training model as `train` scores checkpoints (primitive collision, training terminations, the
randomized physics of `train.scoring_seed`; with `--starts` equal to `train.scoring_starts`, the
same worlds, so scale 1 from frame 0 repeats the logged score). Scale 0 is
zero output: under `selective` the residual joints track the reference and the rest hold the
default pose. Where a smaller scale survives longer, the policy's own outputs end the rollout.
`--joints` scales only the outputs of the policy joints matching those globs (the rest stay whole),
to tell which limbs' outputs do the harm. `--noise-draws K` adds the actor's own Gaussian noise to
the scaled outputs, as training's rollouts do, and gives per start the median over K seeded draws:
at scale 0 that is zero output plus the training noise, to tell whether exploration alone ends a
start's episodes before any output could earn credit there.
Writes `<out>.json` and `<out>.md`.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch

from bench.common import head_commit, write_result
from rd_pipeline.api import workspace
from rd_pipeline.env.mdp.actions import joints_matching
from rd_pipeline.errors import PipelineError
from rd_pipeline.robots import load_robot
from rd_pipeline.sampling.prior import PRIOR_FILE
from rd_pipeline.training.config import clip_frames
from rd_pipeline.training.evaluate import scoring_starts, survival
from rd_pipeline.training.runner import Segments, TrainingJob, TrainingRunner, clip_segments
from rd_pipeline.training.trainer import load_checkpoint


def main() -> None:
    args = _parser().parse_args()
    try:
        result = _measure(args)
    except (PipelineError, ValueError, OSError) as exc:
        sys.exit(f"error: {exc}")
    write_result(args.out, result, _table(result))


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--clip", default="11:21")
    parser.add_argument("--profile", default="cpu")
    parser.add_argument("--iterations", type=int, required=True)
    parser.add_argument("--checkpoint", type=int, default=None, help="its iteration (default: the last)")
    parser.add_argument("--set", nargs="*", default=[], help="further overrides, as the run had them")
    parser.add_argument("--scales", type=float, nargs="+", default=[1.0, 0.5, 0.25, 0.0])
    parser.add_argument("--starts", type=int, default=10)
    parser.add_argument("--joints", nargs="+", default=["*"], help="globs of the policy joints to scale")
    parser.add_argument("--noise-draws", type=int, default=0, help="rollouts with the actor's noise per scale")
    parser.add_argument(
        "--commit", default=None, help="the commit of the installed code that runs this (default: HEAD)"
    )
    parser.add_argument("--out", type=Path, default=Path("studies/results/action_scale"))
    return parser


def _measure(args: argparse.Namespace) -> dict[str, Any]:
    if args.noise_draws < 0:
        raise ValueError(f"--noise-draws {args.noise_draws}: give 0 (no noise) or more draws")
    sets = (f"train.clip={args.clip}", f"train.iterations={args.iterations}", *args.set)
    plan = workspace.plan(args.robot, args.motion, args.profile, overrides=sets)
    train = workspace.required_artifact(plan, "train")
    held = workspace.training_checkpoints(train)
    iteration = args.checkpoint if args.checkpoint is not None else max(held)
    if iteration not in held:
        raise ValueError(f"{train} holds no checkpoint {iteration}")
    runner = _runner(plan, args.starts)
    scaled = _scaled_joints(runner.job.robot.config.policy_joints, args.joints)
    load_checkpoint(held[iteration], runner.learner, runner.env)
    env = runner.scoring_env
    assert env is not None
    fresh = env.state_dict()
    # Worlds that end respawn where the sampler says and draw pushes from the environment's
    # generator: the sampler starts over too, or one scale's rollouts would move the next's.
    fresh_sampler = env.sampler.state_dict()
    starts = scoring_starts(env.max_episode_length, env.num_envs)
    draws = list(range(args.noise_draws)) or [None]
    survival_s = {}
    for scale in args.scales:
        seconds = []
        for draw in draws:
            env.load_state_dict(fresh)
            env.sampler.load_state_dict(fresh_sampler)
            seconds.append(_survival(runner, starts, scale, scaled, draw).numpy())
        survival_s[str(scale)] = [round(float(value), 2) for value in np.median(seconds, axis=0)]
    return {
        "robot": args.robot,
        "motion": args.motion,
        "clip": args.clip,
        "train_key": train.name,
        "checkpoint": iteration,
        "commit": args.commit or head_commit(),
        "scaled_joints": [joint for joint, chosen in zip(runner.job.robot.config.policy_joints, scaled) if chosen],
        "start_s": [round(float(frame) / env.control_hz, 2) for frame in starts],
        "noise_draws": args.noise_draws,
        "noise_std": _noise_std(runner) if args.noise_draws else None,
        "survival_s": survival_s,
    }


def _runner(plan: workspace.Plan, starts: int) -> TrainingRunner:
    """The training's runner, whose scoring environment has one world per start."""
    config = dataclasses.replace(plan.pipeline.params["train"], scoring_starts=starts)
    reference = workspace.reference(plan)
    with np.load(workspace.required_artifact(plan, "prior") / PRIOR_FILE) as prior:
        segments = Segments(prior["starts"], prior["lengths"], prior["weights"])
    start, end = clip_frames(config.clip, reference.fps, reference.n_frames)
    job = TrainingJob(
        load_robot(plan.robot),
        reference.frames(start, end),
        clip_segments(segments, start, end, reference.fps),
        config,
        Path("unused"),
        None,
    )
    return TrainingRunner(job)


def _scaled_joints(policy_joints: tuple[str, ...], globs: list[str]) -> torch.Tensor:
    """(P,) bool: the policy joints whose outputs are scaled."""
    chosen = torch.from_numpy(joints_matching(policy_joints, tuple(globs)))
    if not chosen.any():
        raise ValueError(f"--joints {' '.join(globs)} matches no policy joint ({', '.join(policy_joints)})")
    return chosen


def _survival(
    runner: TrainingRunner, starts: torch.Tensor, scale: float, scaled: torch.Tensor, draw: int | None
) -> torch.Tensor:
    """Seconds survived from each start with the policy's mean outputs on `scaled` joints times
    `scale`, plus the actor's noise seeded by `draw` (None: no noise)."""
    factor = torch.where(scaled, scale, 1.0)
    actor = runner.learner.actor

    def policy(obs):
        if draw is None:
            outputs = actor(obs, stochastic_output=False)
            return outputs * factor.to(outputs)
        sample = actor(obs, stochastic_output=True)
        mean = actor.output_mean
        return mean * factor.to(mean) + (sample - mean)

    if draw is not None:
        torch.manual_seed(draw)
    env = runner.scoring_env
    assert env is not None
    return survival(env, policy, starts)


def _noise_std(runner: TrainingRunner) -> list[float]:
    """The actor's noise std per policy joint, in action units (what the draws added)."""
    std = runner.learner.actor.output_std
    return [round(float(value), 3) for value in std[0]]


def _table(result: dict[str, Any]) -> str:
    scales = list(result["survival_s"])
    noise = " + noise" if result["noise_draws"] else ""
    lines = [
        f"# {result['robot']} {result['motion']} {result['clip']} s, checkpoint {result['checkpoint']} "
        f"(train {result['train_key']}): seconds survived per start on the training model (scoring physics)",
        "",
        f"Scaled outputs: {', '.join(result['scaled_joints'])}.",
        "",
        *_noise_lines(result),
        "| start (s) | " + " | ".join(f"outputs x {scale}{noise}" for scale in scales) + " |",
        "|---|" + "---|" * len(scales),
    ]
    for k, start in enumerate(result["start_s"]):
        cells = [f"{result['survival_s'][scale][k]:.2f}" for scale in scales]
        lines.append(f"| {start:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _noise_lines(result: dict[str, Any]) -> list[str]:
    if not result["noise_draws"]:
        return []
    std = result["noise_std"]
    return [
        f"With the actor's noise (std {min(std):.2f}-{max(std):.2f} action units by joint), "
        f"median of {result['noise_draws']} draws per start.",
        "",
    ]


if __name__ == "__main__":
    main()
