"""`train`: reference + balanced prior -> residual-action PPO policy (checkpoints, log, learning curve)."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rd_pipeline.artifacts.files import open_npz
from rd_pipeline.artifacts.stage import Stage, StageContext
from rd_pipeline.artifacts.store import ArtifactRef
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion import MIN_MOTION_S
from rd_pipeline.params import require_positive
from rd_pipeline.rl.env_config import EnvConfig
from rd_pipeline.rl.ppo_config import PpoConfig
from rd_pipeline.robots.assets import model_files
from rd_pipeline.sampling.sampler import SamplerConfig

CURVE_FILE = "learning_curve.png"
CONTINUED_FILE = "continued_from.txt"
"""Key of the shorter finished run a grown training continued (its first iterations are that run's)."""
PROFILE_FILE = "sampler_profile.png"


@dataclass(frozen=True)
class TrainParams:
    """Training budget and the environment, PPO and sampler settings (profiles set these)."""

    iterations: int = 20_000
    """PPO iterations (paper: 20K for final policies)."""
    checkpoint_every: int = 500
    """Iterations between checkpoints."""
    seed: int = 0
    """Seeds torch, the environment and the sampler."""
    clip: str = ""
    """Train on part of the motion, `START:END` in seconds (empty: all of it)."""
    scoring_starts: int = 8
    """Start frames, evenly spaced over the clip from frame 0, from which each checkpoint is rolled out
    with its mean action on nominal physics; `export` takes the best-scored checkpoint (late PPO
    updates can knock back a policy that had learned the clip)."""
    env: EnvConfig = EnvConfig()
    """Environment."""
    ppo: PpoConfig = PpoConfig()
    """PPO."""
    sampler: SamplerConfig = SamplerConfig()
    """Segment sampler."""

    def __post_init__(self) -> None:
        require_positive(self, "iterations", "checkpoint_every", "scoring_starts")


def clip_frames(clip: str, fps: float, n_frames: int, warn: Callable[[str], None] = print) -> tuple[int, int]:
    """`START:END` seconds -> [start, end) frames of the reference; an END past the motion's end is
    clamped to it, and `warn` says so."""
    if not clip:
        return 0, n_frames
    try:
        start_s, end_s = (float(x) if x else None for x in clip.split(":"))
    except ValueError:
        raise PipelineError(f"train.clip must be START:END in seconds, got '{clip}'") from None
    start = round((start_s or 0.0) * fps)
    end = n_frames if end_s is None else round(end_s * fps)
    if end > n_frames:
        warn(
            f"train.clip '{clip}' ends after the {n_frames / fps:.2f} s motion: training on {start / fps:g}:{n_frames / fps:.2f}"
        )
        end = n_frames
    if not 0 <= start < end - fps * MIN_MOTION_S:
        raise PipelineError(
            f"train.clip '{clip}' leaves less than {MIN_MOTION_S:g} s of the {n_frames / fps:.2f} s motion"
        )
    return start, end


def _run(ctx: StageContext) -> dict[str, Any]:
    import numpy as np
    import torch

    from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
    from rd_pipeline.rl.env import TrackingEnv
    from rd_pipeline.rl.evaluate import checkpoint_scorer, nominal
    from rd_pipeline.rl.ppo import build_ppo
    from rd_pipeline.rl.rewards import GROUPS
    from rd_pipeline.rl.trainer import (
        CHECKPOINT_DIR,
        LOG_FILE,
        best_scored,
        checkpoint_path,
        checkpoints_by_iteration,
        load_checkpoint,
        plot_learning_curve,
        read_training_log,
        train,
    )
    from rd_pipeline.robots import load_robot
    from rd_pipeline.sampling.plots import plot_sampler_profile
    from rd_pipeline.sampling.prior import PRIOR_FILE
    from rd_pipeline.sampling.sampler import SegmentSampler

    p: TrainParams = ctx.params
    torch.manual_seed(p.seed)
    robot = load_robot(ctx.robot)
    reference = ReferenceMotion.load(ctx.upstream["reference"].path / REFERENCE_FILE)
    with open_npz(ctx.upstream["sampling_prior"].path / PRIOR_FILE) as prior:
        weights, starts, lengths = prior["weights"], prior["starts"], prior["lengths"]
    warn = lambda message: ctx.console.print(f"[yellow]warning:[/] {message}", highlight=False)
    start, end = clip_frames(p.clip, reference.fps, reference.n_frames, warn)
    keep = (starts >= start) & (starts + lengths <= end)
    reference = reference.frames(start, end)
    starts, lengths, weights = starts[keep] - start, lengths[keep], weights[keep]
    balanced = torch.as_tensor(weights if weights.sum() > 0 else np.ones(len(weights)))
    sampler = SegmentSampler(p.sampler, balanced, seed=p.seed)
    env = TrackingEnv(robot, reference, sampler, starts, lengths, p.env, seed=p.seed)
    ppo = build_ppo(env.get_observations(), env.num_envs, env.num_actions, len(GROUPS), p.ppo, p.env.device)
    observation_size = int(env.get_observations()["policy"].shape[1])
    scoring_sampler = SegmentSampler(p.sampler, balanced, seed=p.seed)
    scoring_config = nominal(p.env, p.scoring_starts)
    scoring_env = TrackingEnv(robot, reference, scoring_sampler, starts, lengths, scoring_config, seed=p.seed)
    mean_action = lambda obs: ppo.actor(obs, stochastic_output=False)
    # Checkpoints and the log live in the work folder, which survives an interruption; --resume
    # continues from its newest checkpoint, and a fresh run starts it over.
    work = ctx.work_dir or ctx.out_dir
    checkpoints = list(checkpoints_by_iteration(work).values())
    start_iteration = 0
    shorter = None
    if ctx.resume and checkpoints:
        start_iteration = load_checkpoint(checkpoints[-1], ppo, env)
        ctx.console.print(f"  resuming from {checkpoints[-1].name}")
    else:
        if work.exists() and work != ctx.out_dir:
            shutil.rmtree(work)
        if ctx.resume:
            shorter = _longest_shorter_run(ctx.shorter, p.iterations)
    work.mkdir(parents=True, exist_ok=True)
    if shorter is not None:
        # Nothing in training depends on the total number of iterations, so a longer run is the
        # shorter one continued: its log and checkpoints are copied (its final checkpoint among them,
        # even off the checkpoint_every grid) and its last checkpoint resumed.
        shutil.copytree(shorter.path / CHECKPOINT_DIR, work / CHECKPOINT_DIR)
        shutil.copy2(shorter.path / LOG_FILE, work / LOG_FILE)
        done = shorter.manifest["params"]["iterations"]
        start_iteration = load_checkpoint(checkpoint_path(work, done), ppo, env)
        (work / CONTINUED_FILE).write_text(shorter.key + "\n")
        ctx.console.print(f"  continuing the {done}-iteration run {shorter.key}")
    with ctx.progress(p.iterations - start_iteration, f"PPO {ctx.robot}") as advance:
        train(
            env,
            ppo,
            p.iterations,
            work,
            p.checkpoint_every,
            start_iteration=start_iteration,
            on_iteration=lambda row: advance(
                f"reward {row['reward']:.2f}  episode {row['episode_length_s'] or 0:.2f} s"
            ),
            score=checkpoint_scorer(scoring_env, mean_action),
        )
    env.close()
    scoring_env.close()
    rows = read_training_log(work)
    if work != ctx.out_dir:
        for item in work.iterdir():
            shutil.move(str(item), ctx.out_dir / item.name)
        work.rmdir()
    plot_learning_curve(rows, ctx.out_dir / CURVE_FILE)
    plot_sampler_profile(
        sampler.failure_rate.numpy(),
        sampler.probabilities().numpy(),
        1 / sampler.n_segments,
        ctx.out_dir / PROFILE_FILE,
    )
    last = rows[-1]
    # The last iteration is always a scored checkpoint, so there is a best one.
    best = best_scored(rows)
    continued = ctx.out_dir / CONTINUED_FILE
    return {
        "iterations": p.iterations,
        "continued_from": continued.read_text().strip() if continued.exists() else None,
        "num_envs": p.env.num_envs,
        "clip_frames": [start, end],
        "observation_size": observation_size,
        "num_actions": env.num_actions,
        "final_episode_length_s": last["episode_length_s"],
        "final_reward": last["reward"],
        "final_start_zero_s": last["start_zero_s"],
        "best_checkpoint": best["iteration"],
        "best_start_zero_s": best["start_zero_s"],
        "best_completion": best["completion"],
        "samples_per_s_median": float(np.median([r["samples_per_s"] for r in rows])),
        "sampler_step": sampler.step,
    }


def _longest_shorter_run(runs: tuple[ArtifactRef, ...], iterations: int) -> ArtifactRef | None:
    """The finished run with the most iterations below `iterations`, if any."""
    below = [run for run in runs if run.manifest["params"]["iterations"] < iterations]
    return max(below, key=lambda run: run.manifest["params"]["iterations"], default=None)


STAGE = Stage(
    name="train",
    version=4,
    description="reference + prior -> residual-action PPO policy (multi-head critic, segment sampler)",
    params=TrainParams,
    provides="policy",
    run=_run,
    inputs=lambda robot, motion: model_files(robot),
    requires=("reference", "sampling_prior"),
    headline=("iterations", "best_checkpoint", "best_start_zero_s", "samples_per_s_median"),
    extends=("iterations",),
)
