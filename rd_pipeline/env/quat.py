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


def multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """The rotation `b` then `a`: the Hamilton product a * b of (..., 4) quaternions."""
    aw = a[..., :1]
    bw = b[..., :1]
    av = a[..., 1:]
    bv = b[..., 1:]
    w = aw * bw - (av * bv).sum(-1, keepdim=True)
    v = aw * bv + bw * av + torch.cross(av, bv, dim=-1)
    return torch.cat([w, v], dim=-1)


def from_rotation_vector(rotvec: torch.Tensor) -> torch.Tensor:
    """(..., 4) unit quaternions of (..., 3) rotation vectors (axis times angle in radians)."""
    angle = rotvec.norm(dim=-1, keepdim=True)
    half = 0.5 * angle
    # sin(x/2)/x -> 1/2 as x -> 0: the series keeps tiny rotations exact.
    scale = torch.where(angle > 1e-8, torch.sin(half) / angle.clamp(min=1e-8), 0.5 - angle**2 / 48.0)
    return torch.cat([torch.cos(half), rotvec * scale], dim=-1)
