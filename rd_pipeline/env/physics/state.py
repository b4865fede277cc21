"""What a physics backend is: the state it hands the environment and the protocol it implements,
with the helpers the backends share."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import mujoco
import numpy as np
import torch


@dataclass
class PhysicsState:
    """What the environment reads after a control step (torch, per environment, on the backend's device)."""

    qpos: torch.Tensor
    """(N, nq)"""
    qvel: torch.Tensor
    """(N, nv)"""
    body_pos: torch.Tensor
    """(N, nbody, 3) world positions."""
    body_quat: torch.Tensor
    """(N, nbody, 4) world orientations, wxyz."""
    body_vel: torch.Tensor
    """(N, nbody, 6) world-frame [angular, linear] velocities at the body origins."""
    actuator_force: torch.Tensor
    """(N, nu) applied (clipped) PD torques of the last physics step."""
    contact_force: torch.Tensor
    """(N, nbody, 3) summed contact force on each body (world frame)."""


class PhysicsBackend(Protocol):
    """What the environment needs from physics; `models[i]` is environment i's (randomized) model."""

    num_envs: int
    models: list[mujoco.MjModel]
    state: PhysicsState
    device: torch.device

    def set_state(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None: ...

    def step(self, ctrl: torch.Tensor, substeps: int, joint_force: torch.Tensor | None = None) -> PhysicsState: ...

    def push(self, env_ids: torch.Tensor, planar_velocity: torch.Tensor) -> None: ...

    def get_states(self) -> np.ndarray: ...

    def set_states(self, states: np.ndarray) -> None: ...

    def diagnostics(self) -> dict[str, float]:
        """Contact, constraint and solver figures since the last call, then reset (the keys are in
        each backend's docstring; `contacts_peak_world` and `constraints_peak_world` in all). May
        wait for the device: call it once per training iteration."""
        ...

    def close(self) -> None: ...


def state_buffers(num_envs: int, model: mujoco.MjModel) -> tuple[dict[str, np.ndarray], PhysicsState]:
    """Zeroed numpy buffers for every `PhysicsState` field, and the state as zero-copy torch views
    of them (CPU backends fill the buffers; the environment reads the views)."""
    n = num_envs
    buffers = {
        "qpos": np.zeros((n, model.nq)),
        "qvel": np.zeros((n, model.nv)),
        "body_pos": np.zeros((n, model.nbody, 3)),
        "body_quat": np.zeros((n, model.nbody, 4)),
        "body_vel": np.zeros((n, model.nbody, 6)),
        "actuator_force": np.zeros((n, model.nu)),
        "contact_force": np.zeros((n, model.nbody, 3)),
    }
    return buffers, PhysicsState(**{name: torch.from_numpy(array) for name, array in buffers.items()})


def body_velocities(xpos: np.ndarray, cvel: np.ndarray, root_com: np.ndarray) -> np.ndarray:
    """(..., nbody, 6) world [angular, linear] velocity at each body origin from MuJoCo's `cvel`
    (spatial velocity at the tree's centre of mass `root_com` = subtree_com[body_rootid]); what
    `mj_objectVelocity` does, for all bodies at once."""
    angular = cvel[..., :3]
    linear = cvel[..., 3:]
    return np.concatenate([angular, linear - np.cross(xpos - root_com, angular)], axis=-1)


def body_velocities_torch(xpos: torch.Tensor, cvel: torch.Tensor, root_com: torch.Tensor) -> torch.Tensor:
    """`body_velocities` on torch tensors (batched backends keep them on their device)."""
    angular = cvel[..., :3]
    linear = cvel[..., 3:]
    return torch.cat([angular, linear - torch.cross(xpos - root_com, angular, dim=-1)], dim=-1)
