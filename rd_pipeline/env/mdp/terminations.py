"""Termination terms: when a tracking episode (training) or a rollout (sim2sim) has failed.

`motion_far` and `bad_orientation` are pure torch functions of robot and reference state, shared by
the training environment and the validation deploy loop so both judge failure the same way. The
training environment ends an episode when any registered term fires: a new termination is one
`@termination_term` function here, reading its thresholds from `TerminationsConfig`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rd_pipeline.env.mdp.reward_terms import TrackingState
from rd_pipeline.env.quat import projected_gravity
from rd_pipeline.lazy import lazy_import

if TYPE_CHECKING:
    import torch
else:
    torch = lazy_import("torch")


@dataclass(frozen=True)
class TerminationsConfig:
    """Failure tests (paper, Table "Control, Initialization, and Termination Parameters")."""

    orientation_limit_rad: float = 0.75
    """Root gravity direction farther than this from the reference's."""
    motion_far_init_m: float = 0.5
    """A termination body farther than this from its reference, at the start of training (the
    motion-far curriculum moves it between `motion_far_min_m` and `motion_far_max_m`)."""
    motion_far_min_m: float = 0.3
    """The curriculum never tightens the motion-far distance below this ..."""
    motion_far_max_m: float = 0.5
    """... nor loosens it above this."""
    motion_far_height_only: bool = False
    """Count only a termination body's height error (BeyondMimic's and mjlab's lenient `z_only`
    terminations on the anchor and end effectors): a hand off to the side of its reference keeps
    the episode, a pelvis sinking or a foot lifting ends it. Training only: validation judges
    with the paper's terms."""


def motion_gap(body_pos: torch.Tensor, ref_body_pos: torch.Tensor, height_only: bool = False) -> torch.Tensor:
    """(N, B) how far each of the (N, B, 3) bodies is from its reference (with `height_only`,
    above or below it)."""
    offset = body_pos - ref_body_pos
    return offset[..., 2].abs() if height_only else offset.norm(dim=-1)


def motion_far(
    body_pos: torch.Tensor, ref_body_pos: torch.Tensor, limit_m: float, height_only: bool = False
) -> torch.Tensor:
    """(N,) True where any of the (N, B, 3) bodies is farther than `limit_m` from its reference
    (with `height_only`, above or below it)."""
    return motion_gap(body_pos, ref_body_pos, height_only).max(dim=-1).values > limit_m


def bad_orientation(root_quat: torch.Tensor, ref_root_quat: torch.Tensor, limit_rad: float) -> torch.Tensor:
    """(N,) True where the root's gravity direction is more than `limit_rad` from the reference's."""
    cosine = (projected_gravity(root_quat) * projected_gravity(ref_root_quat)).sum(-1)
    return torch.acos(cosine.clamp(-1.0, 1.0)) > limit_rad


@dataclass(frozen=True)
class TerminationContext:
    """What the termination terms read besides the tracking state."""

    config: TerminationsConfig
    """The thresholds."""
    root: int
    """Index of the root among the tracked bodies."""
    bodies: torch.Tensor
    """Indices of the termination bodies among the tracked bodies."""
    motion_far_m: float
    """The motion-far distance the curriculum has reached."""


TerminationTerm = Callable[[TrackingState, TerminationContext], "torch.Tensor"]

TERMINATION_TERMS: dict[str, TerminationTerm] = {}
"""Term name -> function, in the order they are evaluated."""


def termination_term(function: TerminationTerm) -> TerminationTerm:
    """Register `function` as a termination term under its name."""
    TERMINATION_TERMS[function.__name__] = function
    return function


@termination_term
def far_from_motion(s: TrackingState, c: TerminationContext) -> torch.Tensor:
    """A termination body farther than the curriculum's motion-far distance from its reference."""
    bodies = c.bodies
    return motion_far(s.body_pos[:, bodies], s.ref_body_pos[:, bodies], c.motion_far_m, c.config.motion_far_height_only)


@termination_term
def root_tilted(s: TrackingState, c: TerminationContext) -> torch.Tensor:
    """The root's gravity direction too far from the reference's."""
    return bad_orientation(s.body_quat[:, c.root], s.ref_body_quat[:, c.root], c.config.orientation_limit_rad)


def failed(state: TrackingState, context: TerminationContext) -> torch.Tensor:
    """(N,) True where any termination term fires."""
    terms = iter(TERMINATION_TERMS.values())
    result = next(terms)(state, context)
    for term in terms:
        result = result | term(state, context)
    return result
