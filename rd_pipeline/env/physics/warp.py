"""MuJoCo Warp physics backend: every environment is one world of a single batched Warp model.

Same seam as `MujocoCpuBackend` (the environment logic does not change). Domain-randomized fields
that differ between environments (link mass and inertia, friction, pelvis COM, PD gains) become per-world
arrays. State comes and goes as torch tensors that share memory with Warp's arrays
(`wp.to_torch`), so on a GPU nothing crosses to the host between physics and learning.

On a CUDA device that allows it (`capture_blocker`), the physics of a control step (its substeps
and the kinematics the environment reads) is one CUDA graph, and a reset's `forward` another;
elsewhere (Warp's CPU device in the tests, an old driver) the same kernels launch one by one and
`capture_fallback_reason` says why (`cpu_graphs` records graphs on Warp's CPU device too). Torch runs on its legacy default stream, which orders itself
with Warp's blocking stream, so torch writes and graph replays never race. Install with the `gpu`
extra.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np
import torch

from rd_pipeline.env.physics.state import PhysicsState, body_velocities_torch
from rd_pipeline.env.sim_model import RANDOMIZED_FIELDS
from rd_pipeline.errors import PipelineError

try:
    import mujoco_warp as mjw
    import warp as wp
except ImportError:
    raise PipelineError("the warp backend needs the gpu extra: pip install 'rd-pipeline[gpu]'") from None

wp.config.log_level = wp.LOG_WARNING  # before Warp initializes: no banner, no line per module load

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

if TYPE_CHECKING:
    IntArray = Any  # Warp's array stubs are not kernel annotations mypy can check
else:
    IntArray = wp.array(dtype=int)

CONDITIONAL_GRAPHS = (12, 4)
"""CUDA driver and toolkit version from which graphs have conditional nodes: MuJoCo Warp's
solver iterates inside the graph (`wp.capture_while`) until every world has converged."""


def capture_blocker(device: str) -> str | None:
    """Why the physics on Warp `device` cannot be captured into CUDA graphs, in one line, or None
    when it can: a CUDA device, a memory pool (a step allocates scratch, which a graph under
    capture takes only from a pool) and conditional graph nodes."""
    target = wp.get_device(device)
    if not target.is_cuda:
        return f"Warp device '{device}' is not a CUDA device: no CUDA graphs, kernels launch one by one"
    if not wp.is_mempool_enabled(target) and not wp.is_mempool_supported(target):
        return f"{target.name} has no CUDA memory pool, which MuJoCo Warp needs to allocate during capture"
    if not wp.is_conditional_graph_supported():
        driver = _version(wp.get_cuda_driver_version())
        toolkit = _version(wp.get_cuda_toolkit_version())
        needed = _version(CONDITIONAL_GRAPHS)
        return (
            f"CUDA driver {driver}, Warp built with toolkit {toolkit}: conditional graph nodes "
            f"(MuJoCo Warp's solver loop) need {needed} or later for both"
        )
    return None


def _version(version: tuple[int, int] | None) -> str:
    return "none" if version is None else ".".join(str(part) for part in version)


@wp.kernel
def _count_contacts(nacon: IntArray, worldid: IntArray, counts: IntArray):
    """Contacts of each world (those kept: a full pool drops the rest)."""
    contact = wp.tid()
    if contact < nacon[0]:
        wp.atomic_add(counts, worldid[contact], 1)


@wp.kernel
def _track_peaks(
    contacts: IntArray,
    nefc: IntArray,
    niter: IntArray,
    nacon: IntArray,
    ncollision: IntArray,
    contacts_peak: IntArray,
    nefc_peak: IntArray,
    niter_peak: IntArray,
    niter_sum: IntArray,
    totals_peak: IntArray,
):
    """Raise each world's peaks to this solve's figures; world 0 also those of all worlds."""
    world = wp.tid()
    contacts_peak[world] = wp.max(contacts_peak[world], contacts[world])
    nefc_peak[world] = wp.max(nefc_peak[world], nefc[world])
    niter_peak[world] = wp.max(niter_peak[world], niter[world])
    niter_sum[world] = niter_sum[world] + niter[world]
    if world == 0:
        totals_peak[0] = wp.max(totals_peak[0], nacon[0])
        totals_peak[1] = wp.max(totals_peak[1], ncollision[0])


class ConstraintMonitor:
    """Peak contacts, constraint rows and solver iterations of every world since the last `read`,
    kept on the device by two small kernels after each solve (inside the graphs), so only `read`
    waits for the device."""

    def __init__(self, data: mjw.Data, iterations: int) -> None:
        n = data.nworld
        self.iterations = iterations
        self.counts = wp.zeros(n, dtype=int)
        self.contacts_peak = wp.zeros(n, dtype=int)
        self.nefc_peak = wp.zeros(n, dtype=int)
        self.niter_peak = wp.zeros(n, dtype=int)
        self.niter_sum = wp.zeros(n, dtype=int)
        """Iterations summed over the solves since `read` (int32: 100 per solve lasts 2e7 solves)."""
        self.totals_peak = wp.zeros(2, dtype=int)
        """Most contacts and most broadphase pairs in all worlds together."""
        self.solves = 0
        """Solves tracked since `read`, counted on the host (each launch knows its own)."""

    def track(self, data: mjw.Data) -> None:
        """Launch the tracking of the solve just launched (capturable: no host reads)."""
        self.counts.zero_()
        wp.launch(_count_contacts, dim=data.naconmax, inputs=[data.nacon, data.contact.worldid, self.counts])
        inputs = [self.counts, data.nefc, data.solver_niter, data.nacon, data.ncollision]
        peaks = [self.contacts_peak, self.nefc_peak, self.niter_peak, self.niter_sum, self.totals_peak]
        wp.launch(_track_peaks, dim=data.nworld, inputs=inputs + peaks)

    def read(self, data: mjw.Data) -> dict[str, float]:
        """The figures since the last call (one host sync), then zeroed; see
        `MujocoWarpBackend.diagnostics`."""
        contacts = int(self.contacts_peak.numpy().max())
        totals = self.totals_peak.numpy()
        nefc = int(self.nefc_peak.numpy().max())
        overflow = data.overflow.numpy()
        solves = max(self.solves, 1) * data.nworld
        figures = {
            "contacts_peak_world": contacts,
            "contacts_capacity_world": data.naconmax // data.nworld,
            "contacts_peak_total": int(totals[0]),
            "contacts_capacity_total": data.naconmax,
            "broadphase_pairs_peak": int(totals[1]),
            "constraints_peak_world": nefc,
            "constraints_capacity_world": data.njmax,
            "solver_iterations_max": int(self.niter_peak.numpy().max()),
            "solver_iterations_mean": float(self.niter_sum.numpy().sum()) / solves,
            "solver_iterations_limit": self.iterations,
            "contact_overflow": max(totals) > data.naconmax,
            "constraint_overflow": nefc > data.njmax,
            "overflow_bits": int(np.bitwise_or.reduce(overflow)),
            "overflow_worlds": int(np.count_nonzero(overflow)),
        }
        for array in (self.contacts_peak, self.nefc_peak, self.niter_peak, self.niter_sum, self.totals_peak):
            array.zero_()
        data.overflow.zero_()  # sticky in MuJoCo Warp: zeroed, it says what happened since this call
        self.solves = 0
        return {name: float(value) for name, value in figures.items()}


class MujocoWarpBackend:
    """N worlds of one MuJoCo Warp model and data."""

    def __init__(
        self,
        models: list[mujoco.MjModel],
        device: str = "cuda",
        contacts_per_world: int = 48,
        constraints_per_world: int = 256,
        cpu_graphs: bool = False,
    ) -> None:
        """`contacts_per_world`/`constraints_per_world` size Warp's fixed buffers: a fallen humanoid
        touches the floor at a few dozen points, each a 4-row pyramidal-cone constraint. Contacts
        are pooled (mujoco-warp 4.0: `naconmax` = worlds x `contacts_per_world`, one world may take
        more); constraint rows are per world. `cpu_graphs` records graphs on Warp's CPU device too
        (Warp 1.19 replays them in C++): the graph path of a GPU, exercised without one."""
        if device.startswith("cuda") and not wp.is_cuda_available():
            raise PipelineError(f"train.env.device '{device}': Warp sees no CUDA device here")
        self.wp = wp
        self.mjw = mjw
        """The modules, for benchmarks that drive the model and data themselves."""
        self.models = models
        self.num_envs = len(models)
        # Plain `cuda` is the current GPU, as for torch: each rank of a data-parallel run set its own.
        self.warp_device = f"cuda:{torch.cuda.current_device()}" if device == "cuda" else device
        self.device = torch.device(self.warp_device)
        self.capture_fallback_reason = self._graphs_blocker(cpu_graphs)
        """Why the physics launches kernel by kernel instead of replaying graphs (None: graphs)."""
        base = models[0]
        with wp.ScopedDevice(self.warp_device):
            self.model = self._batched_model(models)
            self.data = mjw.make_data(
                base, nworld=self.num_envs, nconmax=contacts_per_world, njmax=constraints_per_world
            )
            self.monitor = ConstraintMonitor(self.data, base.opt.iterations)
        self.graphs: dict[tuple[str, int], wp.Graph] = {}
        """Captured graphs: ("step", substeps) and ("forward", 0)."""
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

    def _graphs_blocker(self, cpu_graphs: bool) -> str | None:
        """Why this device gets no graphs (None: it does, its memory pool enabled); said once as a
        warning on a CUDA device, where launching kernel by kernel is a fallback."""
        if self.device.type == "cpu":
            return None if cpu_graphs else capture_blocker(self.warp_device)
        reason = capture_blocker(self.warp_device)
        if reason is None:
            wp.set_mempool_enabled(self.warp_device, True)
        else:
            warnings.warn(f"warp backend without CUDA graphs: {reason}", stacklevel=3)
        return reason

    def _batched_model(self, models: list[mujoco.MjModel]):
        """One Warp model of all worlds: the randomized fields that differ become per-world arrays."""
        batched = mjw.put_model(models[0])
        for field in RANDOMIZED_FIELDS:
            values = np.stack([getattr(m, field) for m in models])
            if not np.array_equal(values, np.broadcast_to(values[:1], values.shape)):
                current = getattr(batched, field)
                setattr(batched, field, wp.array(values.astype(np.float32), dtype=current.dtype))
        return batched

    def _launch(self, key: tuple[str, int], kernels: Callable[[], None]) -> None:
        """Run `kernels`: replayed from the graph captured on their first call, or launched one by
        one where capture is not possible (or failed: then from here on, said once)."""
        with wp.ScopedDevice(self.warp_device):
            graph = self.graphs.get(key)
            if graph is None and self.capture_fallback_reason is None:
                graph = self._capture(kernels)
            if graph is None:
                kernels()
                return
            self.graphs[key] = graph
            wp.capture_launch(graph)

    def _capture(self, kernels: Callable[[], None]) -> wp.Graph | None:
        """The graph of `kernels`, or None when capture fails (nothing ran: a capture only records)."""
        try:
            with wp.ScopedCapture() as capture:
                kernels()
        except RuntimeError as error:
            self.capture_fallback_reason = f"graph capture failed: {error}"
            warnings.warn(f"warp backend without graphs: {self.capture_fallback_reason}", stacklevel=4)
            self.graphs.clear()
            return None
        return capture.graph

    def _step_kernels(self, substeps: int) -> None:
        for _ in range(substeps):
            mjw.step(self.model, self.data)
            self.monitor.track(self.data)
        self._refresh_kernels()

    def _forward_kernels(self) -> None:
        mjw.forward(self.model, self.data)
        self.monitor.track(self.data)
        self._refresh_kernels()

    def _refresh_kernels(self) -> None:
        """Kinematics and external forces of the integrated state (a step leaves them one substep
        behind it)."""
        mjw.kinematics(self.model, self.data)
        mjw.com_pos(self.model, self.data)
        mjw.com_vel(self.model, self.data)
        mjw.rne_postconstraint(self.model, self.data)

    def _body_velocities(self) -> PhysicsState:
        """The body velocities of the refreshed state (the other state tensors are views)."""
        v = self.view
        root_com = v["subtree_com"][:, self.root_ids]
        self.state.body_vel = body_velocities_torch(v["xpos"], v["cvel"], root_com)
        return self.state

    def _forward(self) -> None:
        """Every world's derived quantities from its qpos and qvel (the reset graph)."""
        self._launch(("forward", 0), self._forward_kernels)
        self.monitor.solves += 1
        self._body_velocities()

    def set_state(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        ids = env_ids.to(self.device)
        self.view["qpos"][ids] = qpos.to(self.device, torch.float32)
        self.view["qvel"][ids] = qvel.to(self.device, torch.float32)
        self.view["qacc_warmstart"][ids] = 0.0
        self._forward()

    def step(self, ctrl: torch.Tensor, substeps: int, joint_force: torch.Tensor | None = None) -> PhysicsState:
        self.view["ctrl"].copy_(ctrl)
        if joint_force is None:
            self.view["qfrc_applied"].zero_()
        else:
            self.view["qfrc_applied"].copy_(joint_force)
        self._launch(("step", substeps), lambda: self._step_kernels(substeps))
        self.monitor.solves += substeps
        return self._body_velocities()

    def push(self, env_ids: torch.Tensor, planar_velocity: torch.Tensor) -> None:
        ids = env_ids.to(self.device)
        self.view["qvel"][ids, :2] += planar_velocity.to(self.device, torch.float32)

    def diagnostics(self) -> dict[str, float]:
        """Since the last call (one host sync: call it once per training iteration), over every
        solve of every world: `contacts_peak_world` (most contacts in one world) against
        `contacts_capacity_world` (nconmax), `contacts_peak_total` (most in all worlds at once) and
        `broadphase_pairs_peak` against `contacts_capacity_total` (naconmax, the pool that
        overflows), `constraints_peak_world` against `constraints_capacity_world` (njmax);
        `contact_overflow`, `constraint_overflow` (1 when a peak passed its capacity: contacts or rows
        were dropped), `overflow_bits` (MuJoCo Warp's `OverflowType` bits of all worlds, OR-ed) and
        `overflow_worlds` (worlds with any bit); `solver_iterations_max`, `_mean` and `_limit`."""
        return self.monitor.read(self.data)

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
        self._forward()

    def close(self) -> None:
        self.graphs.clear()
