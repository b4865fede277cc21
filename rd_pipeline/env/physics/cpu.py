"""C MuJoCo, one `MjData` per environment, stepped in chunks by worker threads.

MuJoCo releases the GIL inside `mj_step`, so every core is busy; the state tensors are zero-copy
views of the numpy buffers the threads fill.
"""

from __future__ import annotations

import itertools
from concurrent.futures import ThreadPoolExecutor

import mujoco
import numpy as np
import torch

from rd_pipeline.env.physics.state import PhysicsState, body_velocities, state_buffers

CHECKPOINT_STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS | mujoco.mjtState.mjSTATE_WARMSTART
"""What a checkpoint keeps of each world: with the solver's warm start, or a resumed run's next
step starts the solver cold where the uninterrupted one did not, and the two part in the last digits."""


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
        self.peaks = np.zeros((self.num_envs, 2), dtype=np.int64)
        """Per environment, most contacts and constraint rows since `diagnostics`."""

    def set_state(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        qpos_host = qpos.numpy()
        qvel_host = qvel.numpy()
        for k, i in enumerate(env_ids.tolist()):
            data = self.datas[i]
            mujoco.mj_resetData(self.models[i], data)
            data.qpos[:] = qpos_host[k]
            data.qvel[:] = qvel_host[k]
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
        targets = ctrl.numpy().astype(np.float64)
        force = None if joint_force is None else joint_force.numpy()
        stepped = None if active is None else active.numpy()

        def run(chunk: range) -> None:
            for i in chunk:
                if stepped is not None and not stepped[i]:
                    continue
                model = self.models[i]
                data = self.datas[i]
                data.ctrl[:] = targets[i]
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
        # MuJoCo's high-water marks cover every substep; a reset's mj_resetData zeroes them, so
        # they are kept here before that.
        self.peaks[i] = np.maximum(self.peaks[i], (data.maxuse_con, data.maxuse_efc))

    def push(self, env_ids: torch.Tensor, planar_velocity: torch.Tensor) -> None:
        """Add (k, 2) horizontal velocity to the floating base of `env_ids` (a push)."""
        velocity = planar_velocity.numpy()
        for k, i in enumerate(env_ids.tolist()):
            self.datas[i].qvel[:2] += velocity[k]

    def get_states(self) -> np.ndarray:
        """(N, S) full physics state of every environment (for checkpoints)."""
        spec = CHECKPOINT_STATE
        size = mujoco.mj_stateSize(self.models[0], spec)
        out = np.empty((self.num_envs, size))
        for i, (model, data) in enumerate(zip(self.models, self.datas)):
            mujoco.mj_getState(model, data, out[i], spec)
        return out

    def set_states(self, states: np.ndarray) -> None:
        spec = CHECKPOINT_STATE
        for i, (model, data) in enumerate(zip(self.models, self.datas)):
            mujoco.mj_setState(model, data, states[i], spec)
            mujoco.mj_forward(model, data)
            self._read(i)

    def diagnostics(self) -> dict[str, float]:
        """Since the last call: `contacts_peak_world` and `constraints_peak_world`, the most
        contacts and constraint rows in one environment at any physics step. C MuJoCo takes these
        from its arena as needed, with no fixed count to overflow; solver iterations are not kept
        (`solver_niter` is the last substep's only)."""
        for data in self.datas:
            data.maxuse_con = 0
            data.maxuse_efc = 0
        peaks = self.peaks.max(axis=0)
        self.peaks[:] = 0
        return {"contacts_peak_world": float(peaks[0]), "constraints_peak_world": float(peaks[1])}

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()
