"""What a training run is configured by: its budget, the clip, the learner, and the environment,
PPO or TD3 and sampler settings (profiles set these; they are the `train` stage's params)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from rd_pipeline.env.config import EnvConfig
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion import MIN_MOTION_S
from rd_pipeline.params import ParamRangeError, require_positive
from rd_pipeline.sampling.sampler import SamplerConfig
from rd_pipeline.training.ppo_config import PpoConfig
from rd_pipeline.training.td3_config import Td3Config


@dataclass(frozen=True)
class TrainConfig:
    """Training budget and the environment, PPO and sampler settings (profiles set these)."""

    algorithm: Literal["ppo", "td3"] = "ppo"
    """The learner: `ppo` (the paper's, on-policy) or `td3` (off-policy, many updates per sample;
    one process)."""
    iterations: int = 20_000
    """Iterations (paper: 20K PPO iterations for final policies); an iteration collects
    `steps_per_env` steps of every environment, then updates."""
    checkpoint_every: int = 500
    """Iterations between checkpoints."""
    seed: int = 0
    """Seeds torch, the environment and the sampler."""
    ranks: int = 1
    """Training processes (data-parallel PPO through torchrun, gloo on CPU, NCCL on GPUs): each
    steps `env.num_envs` environments, so an iteration learns from ranks x num_envs x
    steps_per_env samples. A checkpoint continues with the number of ranks that made it."""
    clip: str = ""
    """Train on part of the motion, `START:END` in seconds (empty: all of it)."""
    scoring_starts: int = 8
    """Start frames, evenly spaced over the clip from frame 0, from which each checkpoint is rolled out
    with its mean action on the training model under randomized physics (the learning curve's
    score; `export.best_by` may choose a checkpoint by it)."""
    scoring_seed: int = 7_919
    """Seeds the scoring environment's randomized physics, pushes and forces: apart from training's
    `seed` and validation's seeds, so the score is neither's."""
    env: EnvConfig = EnvConfig()
    """Environment."""
    ppo: PpoConfig = PpoConfig()
    """PPO (`algorithm=ppo`)."""
    td3: Td3Config = Td3Config()
    """TD3 (`algorithm=td3`)."""
    sampler: SamplerConfig = SamplerConfig()
    """Segment sampler."""

    def __post_init__(self) -> None:
        require_positive(self, "iterations", "checkpoint_every", "scoring_starts", "ranks")
        clip_seconds(self.clip)

    @property
    def learner(self) -> PpoConfig | Td3Config:
        """The settings of the learner `algorithm` names (its `steps_per_env` and actor
        `hidden_dims` are what the loop and the exporter read)."""
        return self.td3 if self.algorithm == "td3" else self.ppo

    @property
    def samples_per_iteration(self) -> int:
        """Samples one iteration collects over every rank."""
        return self.ranks * self.env.num_envs * self.learner.steps_per_env


def clip_seconds(clip: str) -> tuple[float, float | None]:
    """`START:END` seconds (either may be empty: the motion's start or end) as (start, end or None);
    a malformed or empty range raises `ParamRangeError`, so it is refused when params are read."""
    if not clip:
        return 0.0, None
    parts = clip.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        start = float(parts[0]) if parts[0] else 0.0
        end = float(parts[1]) if parts[1] else None
    except ValueError:
        raise ParamRangeError("clip", f"must be START:END in seconds, got '{clip}'") from None
    if not (math.isfinite(start) and start >= 0):
        raise ParamRangeError("clip", f"must start at 0 s or later, got '{clip}'")
    if end is not None and not (math.isfinite(end) and end > start + MIN_MOTION_S):
        raise ParamRangeError("clip", f"must end more than {MIN_MOTION_S:g} s after it starts, got '{clip}'")
    return start, end


def clip_frames(clip: str, fps: float, n_frames: int, warn: Callable[[str], None] = print) -> tuple[int, int]:
    """`START:END` seconds -> [start, end) frames of the reference; an END past the motion's end is
    clamped to it, and `warn` says so."""
    if not clip:
        return 0, n_frames
    try:
        start_s, end_s = clip_seconds(clip)
    except ParamRangeError as exc:
        raise PipelineError(f"train.{exc}") from None
    start = round(start_s * fps)
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
