"""Physics backends behind one seam: the environment logic (torch) never touches MuJoCo directly.

Backends take and return torch tensors on their device. `MujocoCpuBackend` keeps one `MjData` per
environment and steps chunks of environments in worker threads (MuJoCo releases the GIL inside
`mj_step`), so every core is busy; its state tensors are zero-copy views of the numpy buffers the
threads fill. The MuJoCo Warp backend implements the same protocol on Warp's arrays.
"""

from __future__ import annotations

import itertools
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Protocol

import mujoco
import numpy as np
import torch

from rd_pipeline.errors import PipelineError


@dataclass
class PhysicsState:
    """What the environment reads after a control step (torch, per environment, on the backend's device)."""

    qpos: np.ndarray
    """(N, nq)"""
    qvel: np.ndarray
    """(N, nv)"""
    body_pos: np.ndarray
    """(N, nbody, 3) world positions."""
    body_quat: np.ndarray
    """(N, nbody, 4) world orientations, wxyz."""
    body_vel: np.ndarray
    """(N, nbody, 6) world-frame [angular, linear] velocities at the body origins."""
    actuator_force: np.ndarray
    """(N, nu) applied (clipped) PD torques of the last physics step."""
    contact_force: np.ndarray
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


class MujocoCpuBackend:
    """N environments, each with its own `MjModel` (domain randomization) and `MjData`."""

    def __init__(self, models: list[mujoco.MjModel], threads: int) -> None:
        self.models = models
        self.datas = [mujoco.MjData(m) for m in models]
        self.num_envs = len(models)
        self.device = torch.device("cpu")
        self.threads = max(1, threads)
        self.pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        bounds = np.linspace(0, self.num_envs, self.threads + 1).astype(int)
        self.chunks = [range(a, b) for a, b in itertools.pairwise(bounds) if b > a]
        self.buffers, self.state = state_buffers(self.num_envs, models[0])

    def set_state(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        qpos = qpos.numpy()
        qvel = qvel.numpy()
        for k, i in enumerate(env_ids.tolist()):
            data = self.datas[i]
            mujoco.mj_resetData(self.models[i], data)
            data.qpos[:] = qpos[k]
            data.qvel[:] = qvel[k]
            mujoco.mj_forward(self.models[i], data)
            self._read(i)

    def step(
        self,
        ctrl: torch.Tensor,
        substeps: int,
        joint_force: torch.Tensor | None = None,
        active: torch.Tensor | None = None,
    ) -> PhysicsState:
        """Hold `ctrl` (N, nu) PD targets for `substeps` physics steps, with extra generalized forces
        `joint_force` (N, nv) (random force injection) held over the same steps; environments where
        `active` (N,) is False are left as they are (finished rollouts)."""
        ctrl = ctrl.numpy().astype(np.float64)
        force = None if joint_force is None else joint_force.numpy()
        stepped = None if active is None else active.numpy()

        def run(chunk: range) -> None:
            for i in chunk:
                if stepped is not None and not stepped[i]:
                    continue
                model = self.models[i]
                data = self.datas[i]
                data.ctrl[:] = ctrl[i]
                if force is not None:
                    data.qfrc_applied[:] = force[i]
                mujoco.mj_step(model, data, nstep=substeps)
                self._read(i)

        if self.pool is None:
            run(range(self.num_envs))
        else:
            list(self.pool.map(run, self.chunks))
        return self.state

    def _read(self, i: int) -> None:
        model = self.models[i]
        data = self.datas[i]
        b = self.buffers
        # mj_step leaves kinematics one substep behind the integrated state; refresh positions and velocities.
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_comVel(model, data)
        b["qpos"][i] = data.qpos
        b["qvel"][i] = data.qvel
        b["body_pos"][i] = data.xpos
        b["body_quat"][i] = data.xquat
        b["actuator_force"][i] = data.actuator_force
        b["body_vel"][i] = body_velocities(data.xpos, data.cvel, data.subtree_com[model.body_rootid])
        # External (contact) force on each body, world frame, from one C call instead of a loop over contacts.
        mujoco.mj_rnePostConstraint(model, data)
        b["contact_force"][i] = data.cfrc_ext[:, 3:]

    def push(self, env_ids: torch.Tensor, planar_velocity: torch.Tensor) -> None:
        """Add (k, 2) horizontal velocity to the floating base of `env_ids` (a push)."""
        velocity = planar_velocity.numpy()
        for k, i in enumerate(env_ids.tolist()):
            self.datas[i].qvel[:2] += velocity[k]

    def get_states(self) -> np.ndarray:
        """(N, S) full physics state of every environment (for checkpoints)."""
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        size = mujoco.mj_stateSize(self.models[0], spec)
        out = np.empty((self.num_envs, size))
        for i, (model, data) in enumerate(zip(self.models, self.datas)):
            mujoco.mj_getState(model, data, out[i], spec)
        return out

    def set_states(self, states: np.ndarray) -> None:
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        for i, (model, data) in enumerate(zip(self.models, self.datas)):
            mujoco.mj_setState(model, data, states[i], spec)
            mujoco.mj_forward(model, data)
            self._read(i)

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()


BACKENDS = ("rollout", "cpu", "warp")


def make_backend(name: str, models: list[mujoco.MjModel], threads: int, device: str) -> PhysicsBackend:
    """`rollout`: C MuJoCo batched by `mujoco.rollout` on `threads` threads, GIL released (models
    need `body_sensors`); `cpu`: one C MuJoCo step call per environment from `threads` Python
    threads; `warp`: MuJoCo Warp on `device` (`cuda`, `cuda:N`, or `cpu` for Warp's CPU device)."""
    if name in ("rollout", "cpu") and device != "cpu":
        raise PipelineError(f"train.env.device '{device}' needs the warp backend (train.env.backend=warp)")
    if name == "rollout":
        from rd_pipeline.rl.rollout_backend import MujocoRolloutBackend

        return MujocoRolloutBackend(models, threads)
    if name == "cpu":
        return MujocoCpuBackend(models, threads)
    if name == "warp":
        from rd_pipeline.rl.warp_backend import MujocoWarpBackend

        return MujocoWarpBackend(models, device)
    raise PipelineError(f"train.env.backend must be one of {', '.join(BACKENDS)}, got '{name}'")
