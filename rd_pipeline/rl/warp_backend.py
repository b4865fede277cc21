"""MuJoCo Warp physics backend: every environment is one world of a single batched Warp model.

Same seam as `MujocoCpuBackend` (the environment logic does not change). Domain-randomized fields
that differ between environments (link mass, friction, pelvis COM, PD gains) become per-world
arrays. On a GPU the substeps of a control step are captured once into a CUDA graph; on Warp's CPU
device (tests) they are launched one by one. Install with the `gpu` extra.
"""

from __future__ import annotations

import mujoco
import numpy as np

from rd_pipeline.errors import PipelineError
from rd_pipeline.rl.backend import PhysicsState, body_velocities
from rd_pipeline.rl.sim_model import RANDOMIZED_FIELDS


class MujocoWarpBackend:
    """N worlds of one MuJoCo Warp model and data."""

    def __init__(self, models: list[mujoco.MjModel], device: str | None = None, contacts_per_world: int = 48,
                 constraints_per_world: int = 256) -> None:
        """`contacts_per_world`/`constraints_per_world` size Warp's fixed buffers: a fallen humanoid
        touches the floor at a few dozen points, each a 4-row pyramidal-cone constraint."""
        try:
            import mujoco_warp as mjw
            import warp as wp
        except ImportError:
            raise PipelineError("the warp backend needs the gpu extra: pip install 'rd-pipeline[gpu]'") from None
        wp.config.quiet = True
        self.wp, self.mjw = wp, mjw
        self.models, self.num_envs = models, len(models)
        self.device = device or ("cuda:0" if wp.is_cuda_available() else "cpu")
        base = models[0]
        self.root_ids = base.body_rootid
        with wp.ScopedDevice(self.device):
            self.model = mjw.put_model(base)
            for field in RANDOMIZED_FIELDS:
                values = np.stack([getattr(m, field) for m in models])
                if not np.array_equal(values, np.broadcast_to(values[:1], values.shape)):
                    current = getattr(self.model, field)
                    setattr(self.model, field, wp.array(values.astype(np.float32), dtype=current.dtype))
            self.data = mjw.make_data(base, nworld=self.num_envs, nconmax=contacts_per_world,
                                      njmax=constraints_per_world)
        self.graph = None
        self.graph_substeps = 0
        n = self.num_envs
        self.state = PhysicsState(
            qpos=np.zeros((n, base.nq)), qvel=np.zeros((n, base.nv)), body_pos=np.zeros((n, base.nbody, 3)),
            body_quat=np.zeros((n, base.nbody, 4)), body_vel=np.zeros((n, base.nbody, 6)),
            actuator_force=np.zeros((n, base.nu)), contact_force=np.zeros((n, base.nbody, 3)),
        )

    def _assign(self, name: str, values: np.ndarray) -> None:
        getattr(self.data, name).assign(values.astype(np.float32))

    def _refresh(self) -> PhysicsState:
        """Kinematics and external forces of the integrated state, read back to numpy."""
        mjw, m, d = self.mjw, self.model, self.data
        with self.wp.ScopedDevice(self.device):
            mjw.kinematics(m, d)
            mjw.com_pos(m, d)
            mjw.com_vel(m, d)
            mjw.rne_postconstraint(m, d)
        s = self.state
        s.qpos[:], s.qvel[:] = d.qpos.numpy(), d.qvel.numpy()
        s.body_pos[:], s.body_quat[:] = d.xpos.numpy(), d.xquat.numpy()
        s.actuator_force[:] = d.actuator_force.numpy()
        s.body_vel[:] = body_velocities(s.body_pos, d.cvel.numpy(), d.subtree_com.numpy()[:, self.root_ids])
        s.contact_force[:] = d.cfrc_ext.numpy()[..., 3:]
        return s

    def set_state(self, env_ids: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> None:
        all_qpos, all_qvel = self.data.qpos.numpy(), self.data.qvel.numpy()
        all_qpos[env_ids], all_qvel[env_ids] = qpos, qvel
        self._assign("qpos", all_qpos)
        self._assign("qvel", all_qvel)
        warm = self.data.qacc_warmstart.numpy()
        warm[env_ids] = 0.0
        self._assign("qacc_warmstart", warm)
        with self.wp.ScopedDevice(self.device):
            self.mjw.forward(self.model, self.data)
        self._refresh()

    def step(self, ctrl: np.ndarray, substeps: int, joint_force: np.ndarray | None = None) -> PhysicsState:
        self._assign("ctrl", ctrl)
        self._assign("qfrc_applied", np.zeros(self.data.qfrc_applied.shape) if joint_force is None else joint_force)
        wp = self.wp
        with wp.ScopedDevice(self.device):
            if self.device.startswith("cuda"):
                if self.graph is None or self.graph_substeps != substeps:
                    with wp.ScopedCapture() as capture:
                        for _ in range(substeps):
                            self.mjw.step(self.model, self.data)
                    self.graph, self.graph_substeps = capture.graph, substeps
                wp.capture_launch(self.graph)
            else:
                for _ in range(substeps):
                    self.mjw.step(self.model, self.data)
        return self._refresh()

    def push(self, env_ids: np.ndarray, planar_velocity: np.ndarray) -> None:
        qvel = self.data.qvel.numpy()
        qvel[env_ids, :2] += planar_velocity
        self._assign("qvel", qvel)

    def get_states(self) -> np.ndarray:
        d = self.data
        return np.concatenate([d.qpos.numpy(), d.qvel.numpy(), d.qacc_warmstart.numpy(), d.ctrl.numpy()], axis=1)

    def set_states(self, states: np.ndarray) -> None:
        nq, nv = self.state.qpos.shape[1], self.state.qvel.shape[1]
        self._assign("qpos", states[:, :nq])
        self._assign("qvel", states[:, nq : nq + nv])
        self._assign("qacc_warmstart", states[:, nq + nv : nq + 2 * nv])
        self._assign("ctrl", states[:, nq + 2 * nv :])
        with self.wp.ScopedDevice(self.device):
            self.mjw.forward(self.model, self.data)
        self._refresh()

    def close(self) -> None:
        self.graph = None
