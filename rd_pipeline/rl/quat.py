"""Quaternion helpers in torch (wxyz)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from rd_pipeline.lazy import lazy_import

if TYPE_CHECKING:
    import torch
else:
    torch = lazy_import("torch")


def rotate_inverse(quat: torch.Tensor, vec: torch.Tensor) -> torch.Tensor:
    """Express world vectors `vec` (..., 3) in the frame of `quat` (..., 4): R(q)^T v."""
    w = quat[..., :1]
    xyz = quat[..., 1:]
    t = 2.0 * torch.cross(xyz, vec, dim=-1)
    return vec - w * t + torch.cross(xyz, t, dim=-1)


def projected_gravity(quat: torch.Tensor) -> torch.Tensor:
    """World gravity direction (0, 0, -1) in the body frame."""
    down = torch.zeros(*quat.shape[:-1], 3, dtype=quat.dtype, device=quat.device)
    down[..., 2] = -1.0
    return rotate_inverse(quat, down)
