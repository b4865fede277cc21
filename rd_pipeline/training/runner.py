"""The training runner: builds the environment and PPO from params, learns, resumes, grows, scores.

Like rsl_rl's `OnPolicyRunner`, it owns the loop's surroundings: where checkpoints and the log go,
which checkpoint a run starts from (an interrupted run's newest, or the end of a shorter finished
run it grows), scoring every checkpoint on nominal physics. A `TrainingJob` is everything one
training needs; `run_job` trains it in this process as one rank of `ranks` (`rl.launch` starts the
ranks of a data-parallel run). The `train` stage only loads its inputs and runs the job.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from rd_pipeline.env.tracking_env import TrackingEnv
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.robots import Robot
from rd_pipeline.sampling.sampler import SegmentSampler
from rd_pipeline.training.config import TrainConfig
from rd_pipeline.training.distributed import ONE_PROCESS, Ranks
from rd_pipeline.training.evaluate import checkpoint_scorer, scoring
from rd_pipeline.training.learner import build_learner
from rd_pipeline.training.log import (
    CHECKPOINT_DIR,
    LOG_FILE,
    checkpoint_path,
    checkpoints_by_iteration,
    intact_checkpoints,
    seal_checkpoint,
)
from rd_pipeline.training.trainer import load_checkpoint, train

CONTINUED_FILE = "continued_from.txt"
"""Key of the shorter finished run a grown training continued (its first iterations are that run's)."""


@dataclass(frozen=True)
class ShorterRun:
    """A finished training of the same setup with fewer iterations, which a longer one continues."""

    key: str
    """Its artifact key."""
    folder: Path
    """Its artifact folder (checkpoints and log)."""
    iterations: int
    """How many iterations it ran."""


@dataclass(frozen=True)
class Segments:
    """The clip's 1 s segments and their balanced prior weights."""

    starts: np.ndarray
    """First frame of each segment, in clip frames."""
    lengths: np.ndarray
    """Frames of each segment."""
    weights: np.ndarray
    """Balanced prior w* over the segments (zeros: uniform)."""


@dataclass(frozen=True)
class TrainingJob:
    """Everything one training needs; picklable, so the ranks of a data-parallel run get it too."""

    robot: Robot
    """The robot."""
    reference: ReferenceMotion
    """The clip to track."""
    segments: Segments
    """Its segments and balanced prior."""
    config: TrainConfig
    """The `train` params."""
    work: Path
    """Where checkpoints and the log go."""
    checkpoint: Path | None
    """The checkpoint to continue from (None: from scratch)."""


@dataclass(frozen=True)
class TrainingOutcome:
    """What a finished training reports besides its log, from rank 0's share."""

    observation_size: int
    """Actor observation width."""
    num_actions: int
    """Policy outputs."""
    sampler_step: int
    """Control steps the sampler counted (its failure EMA updates every `update_interval` of them)."""
    failure_rate: np.ndarray
    """(S,) the sampler's failure rate per segment."""
    probabilities: np.ndarray
    """(S,) its final sampling distribution."""


class TrainingRunner:
    """One rank's training environment and learner, and on rank 0 a nominal scoring environment.

    With several `ranks` (data-parallel PPO) each rank steps its own environments and sampler,
    seeded apart, from the same initial weights."""

    def __init__(self, job: TrainingJob, ranks: Ranks = ONE_PROCESS) -> None:
        config = job.config
        segments = job.segments
        torch.manual_seed(config.seed)
        weights = segments.weights
        balanced = torch.as_tensor(weights if weights.sum() > 0 else np.ones(len(weights)))
        seed = ranks.seed(config.seed)
        self.job = job
        self.ranks = ranks
        self.sampler = SegmentSampler(config.sampler, balanced, seed=seed)
        self.env = TrackingEnv(
            job.robot, job.reference, self.sampler, segments.starts, segments.lengths, config.env, seed
        )
        self.learner = build_learner(self.env, config, ranks)
        if ranks.distributed:
            # The weights are rank 0's; the action noise, drawn from torch's generator, is each rank's own.
            torch.manual_seed(seed)
        self.scoring_env: TrackingEnv | None = None
        if ranks.leader:
            self.scoring_env = TrackingEnv(
                job.robot,
                job.reference,
                SegmentSampler(config.sampler, balanced, seed=config.seed),
                segments.starts,
                segments.lengths,
                scoring(config.env, config.scoring_starts),
                seed=config.scoring_seed,
            )

    def learn(self, on_iteration: Callable[[dict], None]) -> None:
        """Train from the job's checkpoint (or scratch) to the configured iterations, checkpointing
        and scoring into the job's work folder."""
        job = self.job
        first = 0
        if job.checkpoint is not None:
            first = load_checkpoint(job.checkpoint, self.learner, self.env, self.ranks)
        mean_action = lambda obs: self.learner.actor(obs, stochastic_output=False)
        score = None if self.scoring_env is None else checkpoint_scorer(self.scoring_env, mean_action)
        train(
            self.env,
            self.learner,
            job.config.iterations,
            job.work,
            job.config.checkpoint_every,
            start_iteration=first,
            on_iteration=on_iteration,
            score=score,
            ranks=self.ranks,
        )

    def outcome(self) -> TrainingOutcome:
        return TrainingOutcome(
            observation_size=int(self.env.get_observations()["policy"].shape[1]),
            num_actions=self.env.num_actions,
            sampler_step=self.sampler.step,
            failure_rate=self.sampler.failure_rate.numpy(),
            probabilities=self.sampler.probabilities().numpy(),
        )

    def close(self) -> None:
        self.env.close()
        if self.scoring_env is not None:
            self.scoring_env.close()


def run_job(job: TrainingJob, on_iteration: Callable[[dict], None], ranks: Ranks = ONE_PROCESS) -> TrainingOutcome:
    """Train `job` as one of `ranks` (the only one by default) and report rank 0's share."""
    runner = TrainingRunner(job, ranks)
    try:
        runner.learn(on_iteration)
        return runner.outcome()
    finally:
        runner.close()


def starting_checkpoint(
    work: Path, restart: bool, shorter: ShorterRun | None, say: Callable[[str], None]
) -> Path | None:
    """Make `work` ready and return the checkpoint to start from: the newest intact one an
    interrupted run left there (unless `restart`; resuming is exact, so the result is that of an
    uninterrupted run), else the end of `shorter` copied in (a longer run is the shorter one
    continued, since nothing in training depends on the total), else None in an emptied folder."""
    if checkpoints_by_iteration(work) and not restart:
        return _continued_checkpoint(work, say)
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    if shorter is None:
        return None
    shutil.copytree(shorter.folder / CHECKPOINT_DIR, work / CHECKPOINT_DIR)
    shutil.copy2(shorter.folder / LOG_FILE, work / LOG_FILE)
    # The artifact's manifest vouched for these files; the seal vouches from now on.
    seal_checkpoint(work, shorter.iterations)
    (work / CONTINUED_FILE).write_text(shorter.key + "\n")
    say(f"  continuing the {shorter.iterations}-iteration run {shorter.key}")
    return checkpoint_path(work, shorter.iterations)


def _continued_checkpoint(work: Path, say: Callable[[str], None]) -> Path:
    """The newest intact checkpoint of an interrupted run; damaged newer ones are named and
    deleted (the run saves them again)."""
    intact, damaged = intact_checkpoints(work)
    if intact is None:
        newest, problem = next(iter(damaged.items()))
        raise PipelineError(
            f"{work}: no checkpoint there can be continued ({newest.name}: {problem}); `--force` starts over"
        )
    for path, problem in damaged.items():
        say(f"  {path.name} is damaged ({problem}): not continued from, deleted")
        path.unlink()
    say(f"  continuing the interrupted run from {intact.name} in {work} (--force starts over)")
    return intact


def clip_segments(segments: Segments, start: int, end: int, fps: float) -> Segments:
    """The segments that lie wholly inside frames [start, end), in clip frames; a clip that holds
    none leaves the sampler nothing to draw from, and is refused."""
    keep = (segments.starts >= start) & (segments.starts + segments.lengths <= end)
    if not keep.any():
        raise PipelineError(
            f"train.clip {start / fps:g}:{end / fps:g} s holds no whole segment of the sampling prior "
            f"(segments of {segments.lengths.max() / fps:g} s from the take's start): widen it"
        )
    return Segments(segments.starts[keep] - start, segments.lengths[keep], segments.weights[keep])


def continued_from(folder: Path) -> str | None:
    """The key of the shorter run a training folder continued, if any."""
    path = folder / CONTINUED_FILE
    return path.read_text().strip() if path.exists() else None


def training_metrics(
    rows: list[dict], outcome: TrainingOutcome, config: TrainConfig, best: dict[str, Any]
) -> dict[str, Any]:
    """The headline figures of a finished training, for its manifest."""
    last = rows[-1]
    return {
        "iterations": config.iterations,
        "num_envs": config.env.num_envs,
        "ranks": config.ranks,
        "samples": config.iterations * config.samples_per_iteration,
        "observation_size": outcome.observation_size,
        "num_actions": outcome.num_actions,
        "final_episode_length_s": last["episode_length_s"],
        "final_reward": last["reward"],
        "final_start_zero_s": last["start_zero_s"],
        "best_checkpoint": best["iteration"],
        "best_start_zero_s": best["start_zero_s"],
        "best_completion": best["completion"],
        "samples_per_s_median": float(np.median([r["samples_per_s"] for r in rows])),
        "nonfinite_resets": sum(r.get("nonfinite_resets", 0) for r in rows),
        "sampler_step": outcome.sampler_step,
    }
