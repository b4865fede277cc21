"""The training runner: builds the environment and PPO from params, learns, resumes, grows, scores.

Like rsl_rl's `OnPolicyRunner`, it owns the loop's surroundings: where checkpoints and the log go,
continuing an interrupted run from its newest checkpoint, growing a finished shorter run, scoring
every checkpoint on nominal physics. The `train` stage only loads its inputs and calls `learn`.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.rl.env import TrackingEnv
from rd_pipeline.rl.evaluate import checkpoint_scorer, nominal
from rd_pipeline.rl.ppo import MultiHeadPPO, build_ppo
from rd_pipeline.rl.rewards import GROUPS
from rd_pipeline.rl.trainer import load_checkpoint, train
from rd_pipeline.rl.training_config import TrainConfig
from rd_pipeline.rl.training_log import (
    CHECKPOINT_DIR,
    LOG_FILE,
    checkpoint_path,
    checkpoints_by_iteration,
    read_training_log,
)
from rd_pipeline.robots import Robot
from rd_pipeline.sampling.sampler import SegmentSampler

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


class TrainingRunner:
    """The training environment, its PPO and a nominal scoring environment, built from params."""

    def __init__(self, robot: Robot, reference: ReferenceMotion, segments: Segments, config: TrainConfig) -> None:
        torch.manual_seed(config.seed)
        weights = segments.weights
        balanced = torch.as_tensor(weights if weights.sum() > 0 else np.ones(len(weights)))
        self.config = config
        self.sampler = SegmentSampler(config.sampler, balanced, seed=config.seed)
        self.env = TrackingEnv(
            robot, reference, self.sampler, segments.starts, segments.lengths, config.env, seed=config.seed
        )
        self.ppo: MultiHeadPPO = build_ppo(
            self.env.get_observations(),
            self.env.num_envs,
            self.env.num_actions,
            len(GROUPS),
            config.ppo,
            config.env.device,
        )
        scoring_sampler = SegmentSampler(config.sampler, balanced, seed=config.seed)
        self.scoring_env = TrackingEnv(
            robot,
            reference,
            scoring_sampler,
            segments.starts,
            segments.lengths,
            nominal(config.env, config.scoring_starts),
            seed=config.seed,
        )

    @property
    def observation_size(self) -> int:
        return int(self.env.get_observations()["policy"].shape[1])

    def prepare(self, work: Path, restart: bool, shorter: ShorterRun | None, say: Callable[[str], None]) -> int:
        """Make `work` ready and return the iteration to start from: the newest checkpoint an
        interrupted run left there (unless `restart`; resuming is exact, so the result is that of an
        uninterrupted run), else the end of `shorter` copied in (a longer run is the shorter one
        continued, since nothing in training depends on the total), else 0 in an emptied folder."""
        checkpoints = list(checkpoints_by_iteration(work).values())
        if checkpoints and not restart:
            say(f"  continuing the interrupted run from {checkpoints[-1].name} in {work} (--force starts over)")
            return load_checkpoint(checkpoints[-1], self.ppo, self.env)
        if work.exists():
            shutil.rmtree(work)
        work.mkdir(parents=True)
        if shorter is None:
            return 0
        shutil.copytree(shorter.folder / CHECKPOINT_DIR, work / CHECKPOINT_DIR)
        shutil.copy2(shorter.folder / LOG_FILE, work / LOG_FILE)
        (work / CONTINUED_FILE).write_text(shorter.key + "\n")
        say(f"  continuing the {shorter.iterations}-iteration run {shorter.key}")
        return load_checkpoint(checkpoint_path(work, shorter.iterations), self.ppo, self.env)

    def learn(self, work: Path, start_iteration: int, on_iteration: Callable[[dict], None]) -> list[dict]:
        """Train from `start_iteration` to the configured iterations, checkpointing and scoring into
        `work`; returns every row of the log, earlier runs' included."""
        mean_action = lambda obs: self.ppo.actor(obs, stochastic_output=False)
        train(
            self.env,
            self.ppo,
            self.config.iterations,
            work,
            self.config.checkpoint_every,
            start_iteration=start_iteration,
            on_iteration=on_iteration,
            score=checkpoint_scorer(self.scoring_env, mean_action),
        )
        return read_training_log(work)

    def close(self) -> None:
        self.env.close()
        self.scoring_env.close()


def clip_segments(segments: Segments, start: int, end: int) -> Segments:
    """The segments that lie wholly inside frames [start, end), in clip frames."""
    keep = (segments.starts >= start) & (segments.starts + segments.lengths <= end)
    return Segments(segments.starts[keep] - start, segments.lengths[keep], segments.weights[keep])


def continued_from(folder: Path) -> str | None:
    """The key of the shorter run a training folder continued, if any."""
    path = folder / CONTINUED_FILE
    return path.read_text().strip() if path.exists() else None


def training_metrics(rows: list[dict], runner: TrainingRunner, best: dict[str, Any]) -> dict[str, Any]:
    """The headline figures of a finished training, for its manifest."""
    last = rows[-1]
    return {
        "iterations": runner.config.iterations,
        "num_envs": runner.config.env.num_envs,
        "observation_size": runner.observation_size,
        "num_actions": runner.env.num_actions,
        "final_episode_length_s": last["episode_length_s"],
        "final_reward": last["reward"],
        "final_start_zero_s": last["start_zero_s"],
        "best_checkpoint": best["iteration"],
        "best_start_zero_s": best["start_zero_s"],
        "best_completion": best["completion"],
        "samples_per_s_median": float(np.median([r["samples_per_s"] for r in rows])),
        "sampler_step": runner.sampler.step,
    }
