"""Termination terms: when a tracking episode (training) or a rollout (sim2sim) has failed.

Pure torch functions of robot and reference state, shared by the training environment and the
validation deploy loop so both judge failure the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

from rd_pipeline.lazy import lazy_import
from rd_pipeline.rl.quat import projected_gravity

torch = lazy_import("torch")


@dataclass(frozen=True)
class TerminationsCfg:
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


def motion_far(body_pos: torch.Tensor, ref_body_pos: torch.Tensor, limit_m: float) -> torch.Tensor:
    """(N,) True where any of the (N, B, 3) bodies is farther than `limit_m` from its reference."""
    gap = (body_pos - ref_body_pos).norm(dim=-1).max(dim=-1).values
    return gap > limit_m


def bad_orientation(root_quat: torch.Tensor, ref_root_quat: torch.Tensor, limit_rad: float) -> torch.Tensor:
    """(N,) True where the root's gravity direction is more than `limit_rad` from the reference's."""
    cosine = (projected_gravity(root_quat) * projected_gravity(ref_root_quat)).sum(-1)
    return torch.acos(cosine.clamp(-1.0, 1.0)) > limit_rad
