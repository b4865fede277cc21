"""Acceptance of the GPU path: MuJoCo Warp physics, the tracking environment and PPO on one device.

    python -m bench.gpu_acceptance [--device cuda] [--envs 1024 4096 8192] [--steps 1000]
        [--iterations 20] [--out bench/results/gpu_acceptance.json]

One command for a GPU machine; on Warp's CPU device it runs at a few environments
(`--device cpu --envs 4 --steps 20 --iterations 2 --steps-per-env 4 --compare-envs 4
--push-interval 0.1 0.2`, about what tests/test_gpu_acceptance.py runs). Prints and writes JSON:

- `versions`: torch (and its CUDA), Warp, mujoco_warp, MuJoCo, the CUDA driver, Warp's toolkit
  and the GPU; `capture`: whether the physics is replayed from CUDA graphs, and why not.
- `envs`, per environment count (G1, training's collision model, domain randomization on, pushes
  every `--push-interval` seconds, actions drawn around zero with the initial policy noise):
  `build_s` (environment built, first reset: kernels compiled or loaded, reset graph captured) and
  `first_step_s` (step graph captured); steady env steps/s and physics steps/s over `--steps`
  steps; raw physics steps/s of the backend stepped back to back (no environment); a split of one
  env step, synchronized around each part: `graph` (the backend's step less `refresh`), `refresh`
  (the refresh kernels timed alone), `reset` (the backend's set_state) and `torch` (the rest);
  Warp kernel and graph launches and host syncs per steady step and in the first step (counted
  by wrapping Warp's launch and synchronize functions, so on CUDA the first step counts the
  kernels its capture records, the solver loop's body once; torch's syncs from its CUDA sync debug
  mode, null on the CPU); peak GPU memory (torch and Warp's memory pool, null on the CPU); the
  backend's `diagnostics()` over the steps (contacts and constraints against capacity, overflow
  bits, solver iterations); worlds whose physics state went non-finite; and `--iterations` PPO
  iterations end to end (`train`): samples/s including the update.
- `c_backend_equality`: the seven `PhysicsState` fields of the warp backend against C MuJoCo
  (`cpu` backend) after `--compare-steps` control steps from the same reference states with the
  same randomized models, PD targets, random joint forces and a push: largest absolute gaps.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

import mujoco
import numpy as np
import torch
import warp as wp

from rd_pipeline import paths
from rd_pipeline.env.config import EnvConfig, Randomization
from rd_pipeline.env.mdp import events
from rd_pipeline.env.mdp.rewards import GROUPS
from rd_pipeline.env.physics import MujocoCpuBackend, PhysicsState
from rd_pipeline.env.physics.warp import MujocoWarpBackend, capture_blocker
from rd_pipeline.env.sim_model import simulation_model
from rd_pipeline.env.tracking_env import TrackingEnv
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.robots import Robot, load_robot
from rd_pipeline.sampling.sampler import SamplerConfig, SegmentSampler
from rd_pipeline.sampling.segments import segment_bounds
from rd_pipeline.training.ppo import build_ppo
from rd_pipeline.training.ppo_config import PpoConfig
from rd_pipeline.training.trainer import train

FIELDS = tuple(PhysicsState.__dataclass_fields__)
"""The seven state fields compared with C MuJoCo."""

COUNTED = ("launch", "launch_tiled", "capture_launch", "synchronize", "synchronize_device", "synchronize_stream")
"""Warp functions wrapped to count launches and host syncs (memsets and copies are not counted)."""


def main(argv: list[str] | None = None) -> dict:
    """Run every measurement; returns what it prints and writes."""
    args = _parser().parse_args(argv)
    torch.manual_seed(args.seed)
    robot = load_robot(args.robot)
    reference = _reference(robot, args.motion)
    result = {
        "command": "python -m bench.gpu_acceptance " + " ".join(sys.argv[1:] if argv is None else argv),
        "device": args.device,
        "robot": args.robot,
        "motion": args.motion,
        "versions": versions(),
        "capture": {"fallback_reason": capture_blocker(_warp_device(args.device))},
        "envs": [measure(args, robot, reference, n) for n in args.envs],
        "c_backend_equality": compare_with_c(args, robot, reference),
    }
    result["capture"]["graphs"] = result["capture"]["fallback_reason"] is None
    text = json.dumps(result, indent=2)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n")
    print(text)
    return result


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda", help="cuda, cuda:N, or cpu (Warp's CPU device)")
    parser.add_argument("--envs", type=int, nargs="+", default=[1024, 4096, 8192])
    parser.add_argument("--steps", type=int, default=1000, help="env steps per count (throughput, stability)")
    parser.add_argument("--split-steps", type=int, default=50, help="env steps of the synchronized split")
    parser.add_argument("--raw-steps", type=int, default=100, help="control steps of raw backend stepping")
    parser.add_argument("--iterations", type=int, default=20, help="PPO iterations end to end per count")
    parser.add_argument("--steps-per-env", type=int, default=PpoConfig().steps_per_env)
    parser.add_argument("--push-interval", type=float, nargs=2, default=[1.0, 2.0], metavar=("LO", "HI"))
    parser.add_argument("--action-std", type=float, default=PpoConfig().init_noise_std)
    parser.add_argument("--compare-envs", type=int, default=16)
    parser.add_argument("--compare-steps", type=int, default=10)
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("bench/results/gpu_acceptance.json"))
    return parser


def _reference(robot: Robot, motion: str) -> ReferenceMotion:
    csv = paths.csv_path(robot.config.name, motion)
    if csv is None or not csv.is_file():
        raise PipelineError(f"no dataset CSV for {robot.config.name} {motion}: set RD_RETARGETED_DIR")
    return import_retargeted_csv(csv, robot, 30.0, 50.0, "cubic", ContactThresholds()).reference


def _warp_device(device: str) -> str:
    return "cuda:0" if device == "cuda" else device


def versions() -> dict:
    """What the run stands on."""
    cuda = torch.cuda.is_available()
    return {
        "python": sys.version.split()[0],
        "torch": torch.__version__,
        "torch_cuda": torch.version.cuda,
        "warp": wp.config.version,
        "mujoco_warp": metadata.version("mujoco-warp"),
        "mujoco": mujoco.__version__,
        "cuda_driver": _version(wp.get_cuda_driver_version()),
        "warp_cuda_toolkit": _version(wp.get_cuda_toolkit_version()),
        "conditional_graphs": wp.is_conditional_graph_supported() if wp.is_cuda_available() else False,
        "gpu": torch.cuda.get_device_name() if cuda else None,
    }


def _version(version: tuple[int, int] | None) -> str | None:
    return None if version is None else ".".join(str(part) for part in version)


def _sync(device: torch.device) -> None:
    """Wait for everything queued on `device` (Warp's streams and torch's)."""
    if device.type == "cuda":
        wp.synchronize_device(str(device))
        torch.cuda.synchronize(device)


def build_env(args: argparse.Namespace, robot: Robot, reference: ReferenceMotion, n: int) -> TrackingEnv:
    """The tracking environment on the warp backend, pushes every `--push-interval` seconds."""
    starts, lengths = segment_bounds(reference.n_frames, 50.0, 1.0, 0.25)
    sampler = SegmentSampler(SamplerConfig(), torch.ones(len(starts)), seed=args.seed)
    randomization = Randomization(push_interval_s=tuple(args.push_interval))
    config = EnvConfig(num_envs=n, backend="warp", device=args.device, randomization=randomization)
    return TrackingEnv(robot, reference, sampler, starts, lengths, config, seed=args.seed)


def measure(args: argparse.Namespace, robot: Robot, reference: ReferenceMotion, n: int) -> dict:
    """Everything measured at `n` environments."""
    device = torch.device(_warp_device(args.device))
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
    began = time.perf_counter()
    env = build_env(args, robot, reference, n)
    build_s = time.perf_counter() - began
    actions = lambda: torch.randn(n, env.num_actions, device=env.device) * args.action_std
    with counting(device) as first:
        began = time.perf_counter()
        env.step(actions())
        _sync(device)
        first_step_s = time.perf_counter() - began
    with watching_nonfinite(env) as bad:
        began = time.perf_counter()
        for _ in range(args.steps):
            env.step(actions())
        _sync(device)
        seconds = time.perf_counter() - began
    backend = _warp(env)
    result = {
        "num_envs": n,
        "build_s": round(build_s, 3),
        "first_step_s": round(first_step_s, 3),
        "first_step_counts": first,
        "steps": args.steps,
        "env_steps_per_s": round(n * args.steps / seconds, 1),
        "env_physics_steps_per_s": round(n * args.steps * env.config.decimation / seconds, 1),
        "nonfinite_worlds": int(bad.sum()),
        "diagnostics": backend.diagnostics(),
        "split_ms_per_env_step": time_split(env, actions, args.split_steps),
        "per_step_counts": counts_per_step(env, actions),
        "raw_physics_steps_per_s": raw_rate(backend, env.config.decimation, args.raw_steps),
        "capture_fallback_reason": backend.capture_fallback_reason,
    }
    result["training"] = train_briefly(env, args)
    result["memory"] = peak_memory(device)
    env.close()
    return result


def _warp(env: TrackingEnv) -> MujocoWarpBackend:
    backend = env.backend
    if not isinstance(backend, MujocoWarpBackend):
        raise PipelineError(f"the environment steps {type(backend).__name__}, not the warp backend")
    return backend


@contextmanager
def watching_nonfinite(env: TrackingEnv) -> Iterator[torch.Tensor]:
    """(N,) flags, raised on the device (no host sync) in every world whose physics state comes back
    from a step with a non-finite value, before the environment sees it."""
    backend = env.backend
    bad = torch.zeros(env.num_envs, dtype=torch.bool, device=env.device)
    step = backend.step

    def checked(*args, **kwargs) -> PhysicsState:
        state = step(*args, **kwargs)
        for name in FIELDS:
            bad.logical_or_(~torch.isfinite(getattr(state, name)).flatten(1).all(1))
        return state

    backend.step = checked  # type: ignore[method-assign]
    try:
        yield bad
    finally:
        backend.step = step  # type: ignore[method-assign]


@contextmanager
def counting(device: torch.device) -> Iterator[dict]:
    """Warp kernel launches (`launch`, `launch_tiled`), graph launches and host syncs
    (`synchronize*`, also inside the solver's host loop when it is not in a graph) while the block
    runs, by wrapping Warp's functions; torch's host syncs from its CUDA sync debug mode (None on
    the CPU). The dict is filled when the block ends."""
    calls = dict.fromkeys(COUNTED, 0)
    originals = {name: getattr(wp, name) for name in COUNTED}
    for name, function in originals.items():
        setattr(wp, name, _counted(calls, name, function))
    cuda = device.type == "cuda"
    counts: dict = {}
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if cuda:
                torch.cuda.set_sync_debug_mode("warn")
            yield counts
    finally:
        if cuda:
            torch.cuda.set_sync_debug_mode("default")
        for name, function in originals.items():
            setattr(wp, name, function)
    syncs = sum("synchroniz" in str(w.message) for w in caught) if cuda else None
    counts["warp_kernel_launches"] = calls["launch"] + calls["launch_tiled"]
    counts["graph_launches"] = calls["capture_launch"]
    counts["warp_host_syncs"] = calls["synchronize"] + calls["synchronize_device"] + calls["synchronize_stream"]
    counts["torch_host_syncs"] = syncs


def _counted(calls: dict, name: str, function: Callable) -> Callable:
    def wrapper(*args, **kwargs):
        calls[name] += 1
        return function(*args, **kwargs)

    return wrapper


def counts_per_step(env: TrackingEnv, actions: Callable[[], torch.Tensor], steps: int = 5) -> dict:
    """`counting` over `steps` env steps, per step."""
    with counting(env.device) as counts:
        for _ in range(steps):
            env.step(actions())
    return {name: None if value is None else value / steps for name, value in counts.items()}


def time_split(env: TrackingEnv, actions: Callable[[], torch.Tensor], steps: int) -> dict:
    """Milliseconds per env step in each part, the device synchronized around every part (so the
    parts add up to more than a free-running step): `graph` is the backend's step (the step graph
    with its refresh, and the torch copies around it) less `refresh` timed alone."""
    backend = _warp(env)
    device = env.device
    spent = {"step": 0.0, "set_state": 0.0}
    originals = {name: getattr(backend, name) for name in spent}

    def timed(name: str) -> Callable:
        def run(*args, **kwargs):
            _sync(device)
            began = time.perf_counter()
            out = originals[name](*args, **kwargs)
            _sync(device)
            spent[name] += time.perf_counter() - began
            return out

        return run

    for name in spent:
        setattr(backend, name, timed(name))
    total = 0.0
    try:
        for _ in range(steps):
            action = actions()
            _sync(device)
            began = time.perf_counter()
            env.step(action)
            _sync(device)
            total += time.perf_counter() - began
    finally:
        for name, function in originals.items():
            setattr(backend, name, function)
    refresh = refresh_seconds(backend, steps)
    ms = lambda seconds: round(1e3 * seconds / steps, 3)
    return {
        "graph": ms(spent["step"] - refresh * steps),
        "refresh": ms(refresh * steps),
        "reset": ms(spent["set_state"]),
        "torch": ms(total - spent["step"] - spent["set_state"]),
        "total": ms(total),
    }


def refresh_seconds(backend: MujocoWarpBackend, repeats: int) -> float:
    """Seconds of the post-step refresh kernels alone, as the step runs them (in a graph where the
    backend captures, else launched one by one)."""
    device = backend.warp_device
    with wp.ScopedDevice(device):
        launch: Callable[[], None] = backend._refresh_kernels
        if backend.capture_fallback_reason is None:
            with wp.ScopedCapture() as capture:
                backend._refresh_kernels()
            launch = lambda: wp.capture_launch(capture.graph)
        launch()
        wp.synchronize_device(device)
        began = time.perf_counter()
        for _ in range(repeats):
            launch()
        wp.synchronize_device(device)
    return (time.perf_counter() - began) / repeats


def raw_rate(backend: MujocoWarpBackend, substeps: int, control_steps: int) -> float:
    """Physics steps/s of the backend's step (its graph, back to back, holding the last targets)."""
    ctrl = backend.view["ctrl"].clone()
    backend.step(ctrl, substeps)
    _sync(backend.device)
    began = time.perf_counter()
    for _ in range(control_steps):
        backend.step(ctrl, substeps)
    _sync(backend.device)
    return round(backend.num_envs * substeps * control_steps / (time.perf_counter() - began), 1)


def train_briefly(env: TrackingEnv, args: argparse.Namespace) -> dict:
    """`--iterations` PPO iterations through the trainer: samples/s including the update (the
    median after the first iteration, which warms up), and whether every figure stayed finite."""
    config = PpoConfig(steps_per_env=args.steps_per_env)
    obs = env.get_observations()
    ppo = build_ppo(obs, env.num_envs, env.num_actions, len(GROUPS), config, str(env.device))
    began = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        rows = train(env, ppo, iterations=args.iterations, out_dir=Path(folder), checkpoint_every=args.iterations)
    seconds = time.perf_counter() - began
    rates = [row["samples_per_s"] for row in rows]
    steady = rates[1:] or rates
    return {
        "iterations_run": len(rows),
        "seconds": round(seconds, 2),
        "samples_per_s": round(statistics.median(steady), 1),
        "samples_per_s_first": rates[0],
        "reward_first": rows[0]["reward"],
        "reward_last": rows[-1]["reward"],
        "finite": all(np.isfinite(row["reward"]) and np.isfinite(row["loss_value"]) for row in rows),
        "nonfinite_resets": sum(row.get("nonfinite_resets", 0) for row in rows),
    }


def peak_memory(device: torch.device) -> dict:
    """Peak GPU memory of this count in MiB: torch's allocator since the count began, Warp's memory
    pool since the process began (it cannot be reset); None on the CPU."""
    if device.type != "cuda":
        return {"torch_max_allocated_mib": None, "warp_mempool_high_mib": None}
    warp_high = wp.get_mempool_used_mem_high(str(device)) if wp.is_mempool_enabled(str(device)) else None
    return {
        "torch_max_allocated_mib": round(torch.cuda.max_memory_allocated(device) / 2**20, 1),
        "warp_mempool_high_mib": None if warp_high is None else round(warp_high / 2**20, 1),
    }


def compare_with_c(args: argparse.Namespace, robot: Robot, reference: ReferenceMotion) -> dict:
    """The warp backend on `--device` against C MuJoCo (`cpu` backend) on the same randomized
    models, states, PD targets, joint forces and push: the largest gap of each state field after
    `--compare-steps` control steps, beside the field's largest magnitude."""
    n = args.compare_envs
    steps = args.compare_steps
    env_config = EnvConfig()
    randomization = env_config.randomization
    rng = np.random.default_rng(args.seed)
    base = simulation_model(robot, env_config.physics_dt, "primitive")
    root = base.body(robot.config.root_body).id
    models, params = events.randomized_models(base, n, randomization, root, rng)
    frames = np.linspace(0, reference.n_frames - steps - 2, n).astype(int)
    qpos, qvel = _reference_states(base, robot, reference, frames)
    c = MujocoCpuBackend(models, threads=1)
    warp = MujocoWarpBackend(models, device=args.device)
    ids = torch.arange(n)
    on_device = lambda tensor: tensor.to(warp.device)
    c.set_state(ids, qpos, qvel)
    warp.set_state(on_device(ids), on_device(qpos), on_device(qvel))
    dof = [base.jnt_dofadr[base.joint(j).id] for j in robot.config.joint_names]
    # Random force injection as training draws it: up to torque_rfi x the world's factor x effort limit.
    force_scale = randomization.torque_rfi * params[:, 8:9] * np.asarray(robot.config.effort_limit)
    for step in range(steps):
        targets = reference.joint_pos[frames + step + 1] + rng.normal(0.0, 0.05, (n, len(dof)))
        ctrl = torch.from_numpy(targets)
        force = torch.zeros(n, base.nv, dtype=torch.float64)
        force[:, dof] = torch.from_numpy(force_scale * rng.uniform(-1.0, 1.0, force_scale.shape))
        if step == steps // 2:
            push = torch.from_numpy(events.push_velocities(randomization, n, rng))
            c.push(ids, push)
            warp.push(on_device(ids), on_device(push))
        c.step(ctrl, env_config.decimation, force)
        warp.step(on_device(ctrl), env_config.decimation, on_device(force))
    ours = {name: getattr(warp.state, name).cpu().numpy() for name in FIELDS}
    theirs = {name: getattr(c.state, name).numpy() for name in FIELDS}
    result = {
        "envs": n,
        "control_steps": steps,
        "max_abs_gap": {name: float(np.abs(ours[name] - theirs[name]).max()) for name in FIELDS},
        "max_abs_value": {name: float(np.abs(theirs[name]).max()) for name in FIELDS},
        "contacts_peak_world": {"c": c.diagnostics()["contacts_peak_world"]},
    }
    result["contacts_peak_world"]["warp"] = warp.diagnostics()["contacts_peak_world"]
    c.close()
    warp.close()
    return result


def _reference_states(
    model: mujoco.MjModel, robot: Robot, reference: ReferenceMotion, frames: np.ndarray
) -> tuple[torch.Tensor, torch.Tensor]:
    """(n, nq), (n, nv) states on the reference at `frames`: its root pose, joint positions and
    joint velocities, the root at rest."""
    qpos = np.zeros((len(frames), model.nq))
    qvel = np.zeros((len(frames), model.nv))
    joints = [model.joint(j).id for j in robot.config.joint_names]
    qpos[:, :3] = reference.root_pos[frames]
    qpos[:, 3:7] = reference.root_quat[frames]
    qpos[:, model.jnt_qposadr[joints]] = reference.joint_pos[frames]
    qvel[:, model.jnt_dofadr[joints]] = reference.joint_vel[frames]
    return torch.from_numpy(qpos), torch.from_numpy(qvel)


if __name__ == "__main__":
    main()
