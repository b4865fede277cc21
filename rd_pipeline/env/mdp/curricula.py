"""Curricula (paper appendix): the motion-far distance and the penalty scale follow the mean
episode length of the environments that just ended; tracking sigmas follow the tracking error."""

from __future__ import annotations

from dataclasses import dataclass

from rd_pipeline.env.mdp.terminations import TerminationsConfig


@dataclass(frozen=True)
class CurriculaConfig:
    """How the termination distance, the penalty scale and the tracking sigmas adapt."""

    degree: float = 1e-5
    """Per-episode change of the motion-far distance and of the penalty scale."""
    down_up: tuple[float, float] = (40.0, 42.0)
    """Mean episode length (steps) below which the curricula ease, above which they tighten."""
    penalty_scale: tuple[float, float, float] = (0.8, 0.8, 1.0)
    """Penalty scale: initial, min, max."""
    adaptive_sigma_alpha: float = 1e-3
    """EMA rate of the adaptive tracking sigma (0 keeps the table values)."""


@dataclass
class CurriculumState:
    """The current values the curricula move."""

    motion_far_m: float
    """Motion-far termination distance."""
    penalty_scale: float
    """Multiplier of the regularization terms."""


def initial_state(cfg: CurriculaConfig, terminations: TerminationsConfig) -> CurriculumState:
    return CurriculumState(motion_far_m=terminations.motion_far_init_m, penalty_scale=cfg.penalty_scale[0])


def update(
    state: CurriculumState, mean_length: float, count: int, cfg: CurriculaConfig, terminations: TerminationsConfig
) -> None:
    """Ease both curricula when `count` episodes just ended shorter than `down_up[0]` on average,
    tighten them when longer than `down_up[1]`."""
    if count == 0:
        return
    down, up = cfg.down_up
    step = cfg.degree * count
    if mean_length < down:
        state.motion_far_m = min(terminations.motion_far_max_m, state.motion_far_m + step)
        state.penalty_scale = max(cfg.penalty_scale[1], state.penalty_scale - step)
    elif mean_length > up:
        state.motion_far_m = max(terminations.motion_far_min_m, state.motion_far_m - step)
        state.penalty_scale = min(cfg.penalty_scale[2], state.penalty_scale + step)
