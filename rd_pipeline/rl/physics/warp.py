"""MuJoCo Warp physics backend: every environment is one world of a single batched Warp model.

Same seam as `MujocoCpuBackend` (the environment logic does not change). Domain-randomized fields
that differ between environments (link mass, friction, pelvis COM, PD gains) become per-world
arrays. State comes and goes as torch tensors that share memory with Warp's arrays
(`wp.to_torch`), so on a GPU nothing crosses to the host between physics and learning. The
substeps of a control step are captured once into a CUDA graph; on Warp's CPU device (tests) they
are launched one by one. Install with the `gpu` extra.
"""

from __future__ import annotations

import mujoco
import numpy as np
import torch

from rd_pipeline.errors import PipelineError
from rd_pipeline.rl.physics.state import PhysicsState, body_velocities_torch
from rd_pipeline.rl.sim_model import RANDOMIZED_FIELDS

VIEWED_FIELDS = (
    "qpos",
    "qvel",
    "ctrl",
    "qfrc_applied",
    "qacc_warmstart",
    "xpos",
    "xquat",
    "cvel",
    "subtree_com",
    "actuator_force",
    "cfrc_ext",
)
"""Warp data fields the backend reads and writes through torch."""


class MujocoWarpBackend:
    """N worlds of one MuJoCo Warp model and data."""

    def __init__(
        self,
        models: list[mujoco.MjModel],
        device: str = "cuda",
        contacts_per_world: int = 48,
        constraints_per_world: int = 256,
    ) -> None:
        """`contacts_per_world`/`constraints_per_world` size Warp's fixed buffers: a fallen humanoid
        touches the floor at a few dozen points, each a 4-row pyramidal-cone constraint."""
        try:
            import mujoco_warp as mjw
            import warp as wp
        except ImportError:
            raise PipelineError("the warp backend needs the gpu extra: pip install 'rd-pipeline[gpu]'") from None
        wp.config.quiet = True  # type: ignore[attr-defined]  # set at runtime; not in the stubs
        if device.startswith("cuda") and not wp.is_cuda_available():
            raise PipelineError(f"train.env.device '{device}': Warp sees no CUDA device here")
        self.wp = wp
        self.mjw = mjw
        self.models = models
        self.num_envs = len(models)
        self.warp_device = "cuda:0" if device == "cuda" else device
        self.device = torch.device(self.warp_device)
        base = models[0]
        with wp.ScopedDevice(self.warp_device):
            self.model = self._batched_model(models)
            self.data = mjw.make_data(
                base, nworld=self.num_envs, nconmax=contacts_per_world, njmax=constraints_per_world
            )
        self.graph = None
        self.graph_substeps = 0
        self.root_ids = torch.as_tensor(base.body_rootid, device=self.device)
        self.view = {name: wp.to_torch(getattr(self.data, name)) for name in VIEWED_FIELDS}
        """Torch tensors sharing memory with the Warp data (writes go straight to the simulation)."""
        v = self.view
        self.state = PhysicsState(
            qpos=v["qpos"],
            qvel=v["qvel"],
            body_pos=v["xpos"],
            body_quat=v["xquat"],
            body_vel=torch.zeros(self.num_envs, base.nbody, 6, device=self.device),
            actuator_force=v["actuator_force"],
            contact_force=v["cfrc_ext"][..., 3:],
        )

    def _batched_model(self, models: list[mujoco.MjModel]):
        """One Warp model of all worlds: the randomized fields that differ become per-world arrays."""
        batched = self.mjw.put_model(models[0])
        for field in RANDOMIZED_FIELDS:
            values = np.stack([getattr(m, field) for m in models])
            if not np.array_equal(values, np.broadcast_to(values[:1], values.shape)):
                current = getattr(batched, field)
                setattr(batched, field, self.wp.array(values.astype(np.float32), dtype=current.dtype))
        return batched

    def _refresh(self) -> PhysicsState:
        """Kinematics and external forces of the integrated state (the state tensors are views)."""
        mjw = self.mjw
        with self.wp.ScopedDevice(self.warp_device):
            mjw.kinematics(self.model, self.data)
            mjw.com_pos(self.model, self.data)
            mjw.com_vel(self.model, self.data)
            mjw.rne_postconstraint(self.model, self.data)
        v = self.view
        root_com = v["subtree_com"][:, self.root_ids]
        self.state.body_vel = body_velocities_torch(v["xpos"], v["cvel"], root_com)
        return self.state

    def set_state(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        ids = env_ids.to(self.device)
        self.view["qpos"][ids] = qpos.to(self.device, torch.float32)
        self.view["qvel"][ids] = qvel.to(self.device, torch.float32)
        self.view["qacc_warmstart"][ids] = 0.0
        with self.wp.ScopedDevice(self.warp_device):
            self.mjw.forward(self.model, self.data)
        self._refresh()

    def step(self, ctrl: torch.Tensor, substeps: int, joint_force: torch.Tensor | None = None) -> PhysicsState:
        self.view["ctrl"].copy_(ctrl)
        if joint_force is None:
            self.view["qfrc_applied"].zero_()
        else:
            self.view["qfrc_applied"].copy_(joint_force)
        wp = self.wp
        with wp.ScopedDevice(self.warp_device):
            if self.warp_device.startswith("cuda"):
                if self.graph is None or self.graph_substeps != substeps:
                    with wp.ScopedCapture() as capture:
                        for _ in range(substeps):
                            self.mjw.step(self.model, self.data)
                    self.graph = capture.graph
                    self.graph_substeps = substeps
                wp.capture_launch(self.graph)
            else:
                for _ in range(substeps):
                    self.mjw.step(self.model, self.data)
        return self._refresh()

    def push(self, env_ids: torch.Tensor, planar_velocity: torch.Tensor) -> None:
        ids = env_ids.to(self.device)
        self.view["qvel"][ids, :2] += planar_velocity.to(self.device, torch.float32)

    def get_states(self) -> np.ndarray:
        v = self.view
        parts = [v["qpos"], v["qvel"], v["qacc_warmstart"], v["ctrl"]]
        return torch.cat(parts, dim=1).cpu().numpy().astype(np.float64)

    def set_states(self, states: np.ndarray) -> None:
        nq = self.view["qpos"].shape[1]
        nv = self.view["qvel"].shape[1]
        values = torch.as_tensor(states, dtype=torch.float32, device=self.device)
        self.view["qpos"].copy_(values[:, :nq])
        self.view["qvel"].copy_(values[:, nq : nq + nv])
        self.view["qacc_warmstart"].copy_(values[:, nq + nv : nq + 2 * nv])
        self.view["ctrl"].copy_(values[:, nq + 2 * nv :])
        with self.wp.ScopedDevice(self.warp_device):
            self.mjw.forward(self.model, self.data)
        self._refresh()

    def close(self) -> None:
        self.graph = None
