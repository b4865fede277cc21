"""Batched C MuJoCo stepping with `mujoco.rollout`: all environments step in C on a persistent
thread pool (one thread per core, the GIL released), and their results come back as arrays.

Each environment is a full physics state (`mjSTATE_FULLPHYSICS`) in one (N, nstate) array; a
control step is one `Rollout.rollout` call of `substeps` steps from those states with the PD
targets and injected joint forces as open-loop controls. Body poses, velocities, net contact forces
and actuator forces are sensors of the model (`simulation_model(..., body_sensors=True)`), read
from the last substep. MuJoCo evaluates sensors before it integrates, so they describe the state
one physics step (2 ms) before the returned `qpos`/`qvel`. The solver's warm start is not part of
the state: every control step starts it cold.
"""

from __future__ import annotations

import mujoco
import numpy as np
import torch
from mujoco import rollout

from rd_pipeline.env.physics.state import PhysicsState, state_buffers
from rd_pipeline.env.sim_model import BODY_SENSORS, actuator_force_index, body_sensor_index

STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS
CONTROL = mujoco.mjtState.mjSTATE_CTRL | mujoco.mjtState.mjSTATE_QFRC_APPLIED


class MujocoRolloutBackend:
    """N environments (one `MjModel` each, for domain randomization) stepped by `mujoco.rollout`."""

    def __init__(self, models: list[mujoco.MjModel], threads: int) -> None:
        self.models = models
        self.num_envs = len(models)
        self.device = torch.device("cpu")
        model = models[0]
        self.threads = max(1, threads)
        self.pool = rollout.Rollout(nthread=self.threads)
        self.datas = [mujoco.MjData(model) for _ in range(self.threads)]
        self.scratch = mujoco.MjData(model)
        self.nstate = mujoco.mj_stateSize(model, STATE)
        self.qpos_slice = slice(1, 1 + model.nq)  # the state starts with the time
        self.qvel_slice = slice(1 + model.nq, 1 + model.nq + model.nv)
        self.index = {name: body_sensor_index(model, name) for name in BODY_SENSORS}
        self.actuator_index = actuator_force_index(model)
        self.full = np.zeros((self.num_envs, self.nstate))
        self.sensors = np.zeros((self.num_envs, model.nsensordata))
        self.buffers, self.state = state_buffers(self.num_envs, model)
        self.buffers["body_quat"][:, 0, 0] = 1.0  # the world body has no sensor
        self._trajectory = np.zeros((0,))
        self._sensor_trajectory = np.zeros((0,))

    def set_state(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        qpos_host = qpos.numpy()
        qvel_host = qvel.numpy()
        data = self.scratch
        for k, i in enumerate(env_ids.tolist()):
            model = self.models[i]
            mujoco.mj_resetData(model, data)
            data.qpos[:] = qpos_host[k]
            data.qvel[:] = qvel_host[k]
            mujoco.mj_forward(model, data)
            mujoco.mj_getState(model, data, self.full[i], STATE)
            self.sensors[i] = data.sensordata
        self._publish(env_ids.numpy())

    def step(
        self,
        ctrl: torch.Tensor,
        substeps: int,
        joint_force: torch.Tensor | None = None,
        active: torch.Tensor | None = None,
    ) -> PhysicsState:
        """Hold `ctrl` (N, nu) and `joint_force` (N, nv) for `substeps` physics steps of every
        environment (or of those where `active` is True)."""
        ids = np.arange(self.num_envs) if active is None else np.flatnonzero(active.numpy())
        if len(ids) == 0:
            return self.state
        model = self.models[0]
        force = np.zeros((len(ids), model.nv)) if joint_force is None else joint_force.numpy()[ids]
        controls = np.concatenate([ctrl.numpy()[ids].astype(np.float64), force], axis=1)
        controls = np.repeat(controls[:, None, :], substeps, axis=1)
        if self._trajectory.shape != (len(ids), substeps, self.nstate):
            self._trajectory = np.zeros((len(ids), substeps, self.nstate))
            self._sensor_trajectory = np.zeros((len(ids), substeps, model.nsensordata))
        models = self.models if len(ids) == self.num_envs else [self.models[i] for i in ids]
        self.pool.rollout(
            models,
            self.datas,
            self.full[ids],
            controls,
            control_spec=CONTROL,
            nstep=substeps,
            state=self._trajectory,
            sensordata=self._sensor_trajectory,
            skip_checks=True,
        )
        self.full[ids] = self._trajectory[:, -1]
        self.sensors[ids] = self._sensor_trajectory[:, -1]
        self._publish(ids)
        return self.state

    def _publish(self, ids: np.ndarray) -> None:
        """Fill the state buffers of environments `ids` from their physics states and sensors."""
        b = self.buffers
        sensors = self.sensors[ids]
        b["qpos"][ids] = self.full[ids, self.qpos_slice]
        b["qvel"][ids] = self.full[ids, self.qvel_slice]
        b["body_pos"][ids, 1:] = sensors[:, self.index["pos"]]
        b["body_quat"][ids, 1:] = sensors[:, self.index["quat"]]
        b["body_vel"][ids, 1:, :3] = sensors[:, self.index["angvel"]]
        b["body_vel"][ids, 1:, 3:] = sensors[:, self.index["linvel"]]
        # The contact sensor reports the force the body exerts; the env wants the force it receives.
        b["contact_force"][ids, 1:] = -sensors[:, self.index["contact_force"]]
        b["actuator_force"][ids] = sensors[:, self.actuator_index]

    def push(self, env_ids: torch.Tensor, planar_velocity: torch.Tensor) -> None:
        """Add (k, 2) horizontal velocity to the floating base of `env_ids` (a push)."""
        ids = env_ids.numpy()
        self.full[ids, self.qvel_slice.start : self.qvel_slice.start + 2] += planar_velocity.numpy()

    def get_states(self) -> np.ndarray:
        return np.concatenate([self.full, self.sensors], axis=1)

    def set_states(self, states: np.ndarray) -> None:
        self.full[:] = states[:, : self.nstate]
        self.sensors[:] = states[:, self.nstate :]
        self._publish(np.arange(self.num_envs))

    def diagnostics(self) -> dict[str, float]:
        """Since the last call: `contacts_peak_world` and `constraints_peak_world`, the most
        contacts and constraint rows in one environment at any physics step of `step` (MuJoCo's
        high-water marks of the rollout threads' datas). C MuJoCo takes these from its arena as
        needed, with no fixed count to overflow; solver iterations are not kept."""
        contacts = max(data.maxuse_con for data in self.datas)
        constraints = max(data.maxuse_efc for data in self.datas)
        for data in self.datas:
            data.maxuse_con = 0
            data.maxuse_efc = 0
        return {"contacts_peak_world": float(contacts), "constraints_peak_world": float(constraints)}

    def close(self) -> None:
        self.pool.close()
