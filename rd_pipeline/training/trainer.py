"""The training loop: rollouts, the learner's updates (multi-head PPO or TD3), checkpoints, resume,
logs, learning curve."""

from __future__ import annotations

import io
import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np
import torch
from tensordict import TensorDict

from rd_pipeline.env.mdp.rewards import GROUPS
from rd_pipeline.env.tracking_env import TrackingEnv
from rd_pipeline.errors import PipelineError
from rd_pipeline.files import write_bytes_whole
from rd_pipeline.training.distributed import ONE_PROCESS, Ranks, gather_to_leader, summed, weights_digest
from rd_pipeline.training.learner import Learner
from rd_pipeline.training.log import LOG_FILE, checkpoint_path, logged_iteration, seal_checkpoint


def rank_state(env: TrackingEnv) -> dict:
    """What one rank needs, besides the shared weights, to continue exactly: its environments,
    its sampler and its random generators."""
    return {
        "sampler": env.sampler.state_dict(),
        "env": env.state_dict(),
        "torch_rng": torch.get_rng_state(),
        # Action noise is drawn on the training device: a CUDA run needs its generators too.
        "cuda_rng": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else None,
    }


def save_checkpoint(folder: Path, iteration: int, learner: Learner, rank_states: list[dict]) -> None:
    """Save the checkpoint of `iteration` into the training `folder` whole (never torn) and seal
    it with its hash and the log's; a folder removed while training ran stops the run."""
    if not folder.is_dir():
        raise PipelineError(f"{folder} was removed while training ran; the run stops (its progress went with it)")
    state = {
        "iteration": iteration,
        "algorithm": learner.save(),
        "learning_rate": learner.learning_rate,
        "ranks": rank_states,
    }
    # Serialized in memory first: torch's file writer turns a full disk into a RuntimeError.
    buffer = io.BytesIO()
    torch.save(state, buffer)
    write_bytes_whole(checkpoint_path(folder, iteration), buffer.getvalue())
    seal_checkpoint(folder, iteration)


def load_checkpoint(path: Path, learner: Learner, env: TrackingEnv, ranks: Ranks = ONE_PROCESS) -> int:
    """Load the shared weights and this rank's state; returns the checkpoint's iteration."""
    state = torch.load(path, weights_only=False, map_location="cpu")
    saved = state["ranks"]
    if len(saved) != ranks.world_size:
        raise PipelineError(
            f"{path}: made by {len(saved)} training processes, resumed with {ranks.world_size}; "
            f"continue it with train.ranks={len(saved)}"
        )
    learner.load(state["algorithm"], None, strict=True)
    learner.learning_rate = state["learning_rate"]
    for group in learner.optimizer.param_groups:
        group["lr"] = learner.learning_rate
    mine = saved[ranks.rank]
    env.sampler.load_state_dict(mine["sampler"])
    env.load_state_dict(mine["env"])
    torch.set_rng_state(mine["torch_rng"])
    if mine.get("cuda_rng") is not None:
        torch.cuda.set_rng_state_all(mine["cuda_rng"])
    return int(state["iteration"])


@dataclass
class Rollout:
    """What one rollout of every environment leaves for the log."""

    lengths: list[float]
    """Lengths (steps) of the episodes that ended."""
    rewards: torch.Tensor
    """(steps, G) mean reward per group."""
    nonfinite: int
    """Worlds whose physics went non-finite (each failed and reset)."""


def train(
    env: TrackingEnv,
    learner: Learner,
    iterations: int,
    out_dir: Path,
    checkpoint_every: int,
    start_iteration: int = 0,
    on_iteration: Callable[[dict], None] = lambda row: None,
    score: Callable[[], dict[str, float]] | None = None,
    ranks: Ranks = ONE_PROCESS,
) -> list[dict]:
    """Train `learner` from `start_iteration` to `iterations`, checkpointing every `checkpoint_every` and at the end.

    `score`, if given, rates the policy at each checkpoint; its figures go into that iteration's log row.
    With several `ranks`, every rank steps its own environments, rank 0 scores and writes the log
    and the checkpoints (with every rank's state), and the others return no rows.
    Returns the logged rows of this call (the log file also holds those of earlier, resumed runs)."""
    history: list[dict] = []
    obs = env.get_observations()
    log = _open_log(out_dir, start_iteration) if ranks.leader else None
    for iteration in range(start_iteration, iterations):
        began = time.perf_counter()
        obs, rollout = _collect(env, learner, obs)
        losses = learner.update()
        row = _log_row(env, learner, iteration + 1, time.perf_counter() - began, rollout, losses, ranks)
        done = iteration + 1
        checkpoint = done % checkpoint_every == 0 or done == iterations
        states = gather_to_leader(ranks, rank_state(env)) if checkpoint else []
        if log is None:
            continue
        if checkpoint and score is not None:
            row.update(score())
        history.append(row)
        log.write(json.dumps(row) + "\n")
        log.flush()
        on_iteration(row)
        if checkpoint:
            save_checkpoint(out_dir, done, learner, states)
    if log is not None:
        log.close()
    return history


def _open_log(out_dir: Path, start_iteration: int) -> TextIO:
    out_dir.mkdir(parents=True, exist_ok=True)
    _drop_rows_after(out_dir / LOG_FILE, start_iteration)
    return (out_dir / LOG_FILE).open("a")


def _collect(env: TrackingEnv, learner: Learner, obs: TensorDict) -> tuple[TensorDict, Rollout]:
    """One rollout of every environment into the learner, and the returns computed."""
    lengths: list[float] = []
    rewards = []
    nonfinite = 0
    cores = torch.get_num_threads()
    # While collecting, the physics threads want the cores: torch's idle workers would spin on
    # them between the policy's small matrix products. The update gets every core.
    torch.set_num_threads(1)
    with torch.inference_mode():
        for _ in range(learner.storage.num_transitions_per_env):
            actions = learner.act(obs)
            obs, reward, dones, extras = env.step(actions)
            learner.process_env_step(obs, reward, dones, extras)
            lengths += extras["episode_length"].tolist()
            nonfinite += extras["nonfinite"]
            rewards.append(reward.mean(0))
        learner.compute_returns(obs)
    torch.set_num_threads(cores)
    return obs, Rollout(lengths, torch.stack(rewards), nonfinite)


def _log_row(
    env: TrackingEnv,
    learner: Learner,
    iteration: int,
    seconds: float,
    rollout: Rollout,
    losses: dict[str, float],
    ranks: Ranks,
) -> dict:
    """One iteration's line of the training log, over every rank's environments."""
    per_rank = rollout.rewards.mean(0).double()
    totals = summed(ranks, [sum(rollout.lengths), len(rollout.lengths), rollout.nonfinite, *per_rank.tolist()])
    length_sum = totals[0]
    ended = totals[1]
    per_group = np.array(totals[3:]) / ranks.world_size
    samples = ranks.world_size * env.num_envs * learner.storage.num_transitions_per_env
    row = {
        "iteration": iteration,
        "seconds": round(seconds, 3),
        "samples_per_s": round(samples / seconds, 1),
        "episode_length_s": round(length_sum / ended / env.control_hz, 4) if ended else None,
        "reward": round(float(per_group.sum()), 4),
        **{f"reward_{g}": round(float(v), 4) for g, v in zip(GROUPS, per_group)},
        **{f"loss_{k}": round(float(v), 4) for k, v in losses.items()},
        "learning_rate": learner.learning_rate,
        "motion_far_m": round(env.curriculum.motion_far_m, 4),
        "penalty_scale": round(env.curriculum.penalty_scale, 4),
        "nonfinite_resets": int(totals[2]),
        # Rank 0's contact and constraint peaks (on Warp also capacities, overflow, solver iterations).
        **{f"physics_{name}": value for name, value in env.backend.diagnostics().items()},
    }
    if ranks.distributed:
        digests = gather_to_leader(ranks, weights_digest(learner.actor) + weights_digest(learner.critic))
        row["rank_weights"] = digests
    return row


def _drop_rows_after(path: Path, iteration: int) -> None:
    """Keep the log rows up to `iteration`: an interrupted run logged iterations past its last
    checkpoint (the last line possibly torn), and the resumed run logs them again."""
    if not path.exists():
        return
    lines = path.read_text().splitlines()
    kept = [line for line in lines if logged_iteration(line) <= iteration]
    if kept == lines:
        return
    partial = path.with_suffix(".partial")
    partial.write_text("".join(line + "\n" for line in kept))
    os.replace(partial, path)
