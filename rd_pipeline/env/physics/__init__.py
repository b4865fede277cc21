"""Physics backends behind one seam: the environment logic (torch) never touches MuJoCo directly.

Backends take and return torch tensors on their device: `rollout` (C MuJoCo batched by
`mujoco.rollout`), `cpu` (C MuJoCo stepped from worker threads) and `warp` (MuJoCo Warp, the
`gpu` extra) implement `PhysicsBackend` (`state.py`).
"""

from __future__ import annotations

import mujoco
import torch

from rd_pipeline.env.physics.cpu import MujocoCpuBackend
from rd_pipeline.env.physics.rollout import MujocoRolloutBackend
from rd_pipeline.env.physics.state import PhysicsBackend, PhysicsState
from rd_pipeline.errors import PipelineError

__all__ = ["BACKENDS", "MujocoCpuBackend", "MujocoRolloutBackend", "PhysicsBackend", "PhysicsState", "make_backend"]

BACKENDS = ("rollout", "cpu", "warp")


def make_backend(name: str, models: list[mujoco.MjModel], threads: int, device: str) -> PhysicsBackend:
    """`rollout`: C MuJoCo batched by `mujoco.rollout` on `threads` threads, GIL released (models
    need `body_sensors`); `cpu`: one C MuJoCo step call per environment from `threads` Python
    threads; `warp`: MuJoCo Warp on `device` (`cuda`, `cuda:N`, or `cpu` for Warp's CPU device)."""
    if name in ("rollout", "cpu") and device != "cpu":
        raise PipelineError(f"train.env.device '{device}' needs the warp backend (train.env.backend=warp)")
    if name == "rollout":
        return MujocoRolloutBackend(models, threads)
    if name == "cpu":
        return MujocoCpuBackend(models, threads)
    if name == "warp":
        # The CPU torch wheel (the default install) would only fail later, deep in Warp's interop.
        if device.startswith("cuda") and not torch.cuda.is_available():
            raise PipelineError(
                f"train.env.device '{device}': torch {torch.__version__} has no CUDA: "
                'install the CUDA build, see docs/training.md "Training on a GPU"'
            )
        # mujoco-warp is an optional extra: imported only when asked for.
        from rd_pipeline.env.physics.warp import MujocoWarpBackend

        return MujocoWarpBackend(models, device)
    raise PipelineError(f"train.env.backend must be one of {', '.join(BACKENDS)}, got '{name}'")
