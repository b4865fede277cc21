"""Benchmark: training throughput of the old path (mesh collision, one `mj_step` call per environment
from Python threads, 500 Hz), the `cpu` profile's path (fitted primitives, batched `mujoco.rollout`,
500 Hz), and the fast path (the same at mjlab's 200 Hz with Newton 10/20, alone and as `--ranks`
data-parallel processes), in one run, interleaved.

    python -m bench.env_throughput [--robot g1] [--envs 128] [--threads 2] [--repeats 5] [--ranks 2]
        [--out bench/results/env_throughput.json]

For each path: env physics steps/s with a zero policy (env steps x decimation); raw batched
stepping of the same models from the same states (for the new path, the env's own
`Rollout.rollout` calls replayed with their states and controls; for the old one, threads of
`mj_step` from copies of the env states: nothing but physics); PPO samples/s including the update
(the `cpu` profile's PPO settings; torch on one thread while collecting and on every core for the
update, as the trainer does); and CPU memory per environment (resident-set growth of building the
path's environments, divided by their number). Medians over `--repeats` blocks; the paths
alternate block by block so both see the same machine. The last line reads
`speedup=<fast path PPO samples/s / old> physics_ratio=<its env physics / its raw batched stepping>`
(every path's ratio to old is in `speedup_by_path`; `fast_bf16` is the fast path with a bf16 update).
The ranks path is real training (`rd_pipeline.training.launch`, `--envs` split over the ranks, the same
total batch): its PPO samples/s is the median of the training log's iterations after the first,
one launch per block; its physics figures are those of the single-process fast path.
With `--paths warp` the MuJoCo Warp backend is measured alone (`--device cuda` on a GPU).
"""

from __future__ import annotations

import argparse
import json
import platform
import resource
import statistics
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch

from rd_pipeline import paths
from rd_pipeline.env.config import EnvConfig
from rd_pipeline.env.mdp.rewards import GROUPS
from rd_pipeline.env.physics.rollout import CONTROL
from rd_pipeline.env.tracking_env import TrackingEnv
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.robots import Robot, load_robot
from rd_pipeline.sampling.sampler import SamplerConfig, SegmentSampler
from rd_pipeline.sampling.segments import segment_bounds
from rd_pipeline.training.config import TrainConfig
from rd_pipeline.training.launch import train_in_processes
from rd_pipeline.training.ppo import build_ppo
from rd_pipeline.training.ppo_config import PpoConfig
from rd_pipeline.training.runner import Segments, TrainingJob

FAST = {"physics_dt": 0.005, "decimation": 4, "solver_iterations": 10, "ls_iterations": 20}
"""mjlab's tracking task: 200 Hz physics, Newton with 10 iterations and 20 line-search steps."""

PATHS = {
    "old": {"backend": "cpu", "collision": "mesh"},
    "new": {"backend": "rollout", "collision": "primitive"},
    "fast": {"backend": "rollout", "collision": "primitive", **FAST},
    "fast_bf16": {"backend": "rollout", "collision": "primitive", **FAST},
    "warp": {"backend": "warp", "collision": "primitive"},
}

PPO = {"fast_bf16": PpoConfig(mixed_precision=True)}
"""PPO settings of the paths that do not train with the `cpu` profile's (the paper's)."""


def main() -> None:
    args = _parser().parse_args()
    robot = load_robot(args.robot)
    reference = import_retargeted_csv(
        paths.csv_path(args.robot, args.motion), robot, 30.0, 50.0, "cubic", ContactThresholds()
    ).reference
    envs, memory_mb = _environments(args, robot, reference)
    rates = _measure(args, envs, robot, reference)
    result = _result(args, envs, rates, memory_mb)
    for env in envs.values():
        env.close()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))
    if "speedup" in result:
        print(f"speedup={result['speedup']:.2f} physics_ratio={result['physics_ratio']:.3f}")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--envs", type=int, default=128)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--paths", nargs="+", default=["old", "new", "fast", "fast_bf16"], choices=list(PATHS))
    parser.add_argument("--ranks", type=int, default=2, help="processes of the ranks path (0: skip it)")
    parser.add_argument("--device", default="cpu", help="torch device for the warp path: cpu or cuda")
    parser.add_argument("--out", type=Path, default=Path("bench/results/env_throughput.json"))
    return parser


def _environments(
    args: argparse.Namespace, robot: Robot, reference: ReferenceMotion
) -> tuple[dict[str, TrackingEnv], dict[str, float]]:
    """Each path's environments, and the resident memory each environment added (MB)."""
    starts, lengths = segment_bounds(reference.n_frames, 50.0, 1.0, 0.25)
    envs = {}
    memory_mb = {}
    for name in args.paths:
        before = _rss_mb()
        sampler = SegmentSampler(SamplerConfig(), torch.ones(len(starts)), seed=0)
        device = args.device if name == "warp" else "cpu"
        config = EnvConfig(num_envs=args.envs, threads=args.threads, device=device, **PATHS[name])
        envs[name] = TrackingEnv(robot, reference, sampler, starts, lengths, config, seed=0)
        memory_mb[name] = (_rss_mb() - before) / args.envs
    return envs, memory_mb


def _measure(
    args: argparse.Namespace, envs: dict[str, TrackingEnv], robot: Robot, reference: ReferenceMotion
) -> dict[str, dict[str, list[float]]]:
    """Every path's rates, block by block in turn so that all see the same machine."""
    rates: dict[str, dict[str, list[float]]] = {name: {"env": [], "raw": [], "ppo": []} for name in envs}
    ppos = {
        name: build_ppo(
            env.get_observations(),
            args.envs,
            env.num_actions,
            len(GROUPS),
            PPO.get(name, PpoConfig()),
            env.config.device,
        )
        for name, env in envs.items()
    }
    ranked = args.ranks > 1 and "fast" in envs
    if ranked:
        rates["fast_ranks"] = {"ppo": []}
    for _ in range(args.repeats):
        for name, env in envs.items():
            rate, calls = _env_rate(env)
            rates[name]["env"].append(rate)
            rates[name]["raw"].append(_raw_rate(env, args.threads, calls))
            rates[name]["ppo"].append(_ppo_rate(env, ppos[name]))
        if ranked:
            rates["fast_ranks"]["ppo"].append(_ranks_rate(robot, reference, args))
    return rates


def _cpu_model() -> str:
    """The processor's name, since the same two cores differ by 1.6x between hosts."""
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def _result(
    args: argparse.Namespace,
    envs: dict[str, TrackingEnv],
    rates: dict[str, dict[str, list[float]]],
    memory_mb: dict[str, float],
) -> dict[str, Any]:
    result: dict[str, Any] = {
        "robot": args.robot,
        "motion": args.motion,
        "envs": args.envs,
        "threads": args.threads,
        "repeats": args.repeats,
        "cpu": _cpu_model(),
        "paths": {},
    }
    for name in envs:
        measured = rates[name]
        result["paths"][name] = {
            **PATHS[name],
            "mixed_precision": PPO.get(name, PpoConfig()).mixed_precision,
            "cpu_memory_mb_per_env": round(memory_mb[name], 2),
            "env_physics_steps_per_s": round(statistics.median(measured["env"])),
            "raw_batched_steps_per_s": round(statistics.median(measured["raw"])),
            "ppo_samples_per_s_including_update": round(statistics.median(measured["ppo"]), 1),
            "samples": {key: [round(v) for v in values] for key, values in measured.items()},
        }
    if "fast_ranks" in rates:
        measured_ranks = rates["fast_ranks"]["ppo"]
        result["paths"]["fast_ranks"] = {
            **PATHS["fast"],
            "ranks": args.ranks,
            "envs_per_rank": args.envs // args.ranks,
            "threads_per_rank": max(1, args.threads // args.ranks),
            "ppo_samples_per_s_including_update": round(statistics.median(measured_ranks), 1),
            "samples": {"ppo": [round(v) for v in measured_ranks]},
        }
    if "old" in envs and "fast" in envs:
        result.update(_speedups(result["paths"]))
    return result


def _speedups(paths_result: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Every path's PPO samples/s against the old path's; the fast path's physics against its raw stepping."""
    old = paths_result["old"]["ppo_samples_per_s_including_update"]
    fast = paths_result["fast"]
    return {
        "speedup_by_path": {
            name: round(path["ppo_samples_per_s_including_update"] / old, 2) for name, path in paths_result.items()
        },
        "speedup": round(fast["ppo_samples_per_s_including_update"] / old, 2),
        "physics_ratio": round(fast["env_physics_steps_per_s"] / fast["raw_batched_steps_per_s"], 3),
    }


def _env_rate(env: TrackingEnv, steps: int = 50) -> tuple[float, list]:
    """Env physics steps/s with a zero policy, and (for the rollout backend) the physics calls it
    made: states, controls and step counts, to replay without the environment."""
    zero = torch.zeros(env.num_envs, env.num_actions, device=env.device)
    calls: list = []
    backend = env.backend
    if env.config.backend == "rollout":
        pool = backend.pool
        original = pool.rollout

        def recording(models, datas, states, controls, **kwargs):
            calls.append((models, states.copy(), controls.copy(), kwargs["nstep"]))
            return original(models, datas, states, controls, **kwargs)

        pool.rollout = recording
    cores = torch.get_num_threads()
    torch.set_num_threads(1)  # as the trainer collects rollouts
    began = time.perf_counter()
    for _ in range(steps):
        env.step(zero)
    seconds = time.perf_counter() - began
    torch.set_num_threads(cores)
    if calls:
        pool.rollout = original
    return env.num_envs * steps * env.config.decimation / seconds, calls


def _raw_rate(env: TrackingEnv, threads: int, calls: list, control_steps: int = 50) -> float:
    """Physics alone on the env's own models: for the rollout backend, the env's own rollout calls
    replayed (same models, states and controls); for the threaded backend, `mj_step` from copies of
    the environments' current states, in the same threads."""
    backend = env.backend
    decimation = env.config.decimation
    if env.config.backend == "rollout":
        model = backend.models[0]
        steps = 0
        began = time.perf_counter()
        for models, states, controls, nstep in calls:
            trajectory = np.zeros((len(states), nstep, backend.nstate))
            sensors = np.zeros((len(states), nstep, model.nsensordata))
            backend.pool.rollout(
                models,
                backend.datas,
                states,
                controls,
                control_spec=CONTROL,
                nstep=nstep,
                state=trajectory,
                sensordata=sensors,
                skip_checks=True,
            )
            steps += len(states) * nstep
        return steps / (time.perf_counter() - began)
    if env.config.backend == "warp":
        return _raw_warp_rate(backend, control_steps * decimation)
    datas = []
    for model, data in zip(backend.models, backend.datas):
        copy = mujoco.MjData(model)
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        state = np.empty(mujoco.mj_stateSize(model, spec))
        mujoco.mj_getState(model, data, state, spec)
        mujoco.mj_setState(model, copy, state, spec)
        datas.append(copy)
    chunks = np.array_split(np.arange(env.num_envs), threads)

    def run(chunk: np.ndarray) -> None:
        for _ in range(control_steps):
            for i in chunk:
                mujoco.mj_step(backend.models[i], datas[i], nstep=decimation)

    began = time.perf_counter()
    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(run, chunks))
    return env.num_envs * control_steps * decimation / (time.perf_counter() - began)


def _raw_warp_rate(backend, steps: int) -> float:
    """`mujoco_warp.step` on the backend's batched model and data, 10 steps per launch."""
    wp = backend.wp
    mjw = backend.mjw
    with wp.ScopedDevice(backend.warp_device):
        if backend.warp_device.startswith("cuda"):
            with wp.ScopedCapture() as capture:
                for _ in range(10):
                    mjw.step(backend.model, backend.data)
            launch = lambda: wp.capture_launch(capture.graph)
        else:
            launch = lambda: [mjw.step(backend.model, backend.data) for _ in range(10)]
        launch()
        wp.synchronize()
        began = time.perf_counter()
        for _ in range(steps // 10):
            launch()
        wp.synchronize()
    return backend.num_envs * steps / (time.perf_counter() - began)


def _ppo_rate(env: TrackingEnv, ppo, iterations: int = 2) -> float:
    obs = env.get_observations()
    cores = torch.get_num_threads()
    began = time.perf_counter()
    for _ in range(iterations):
        torch.set_num_threads(1)
        with torch.inference_mode():
            for _ in range(ppo.storage.num_transitions_per_env):
                actions = ppo.act(obs)
                obs, reward, dones, extras = env.step(actions)
                ppo.process_env_step(obs, reward, dones, extras)
            ppo.compute_returns(obs)
        torch.set_num_threads(cores)
        ppo.update()
    return iterations * ppo.storage.num_transitions_per_env * env.num_envs / (time.perf_counter() - began)


def _ranks_rate(robot: Robot, reference: ReferenceMotion, args: argparse.Namespace, iterations: int = 4) -> float:
    """PPO samples/s of a real data-parallel training of the fast path: `args.ranks` processes
    sharing `args.envs` environments; the median of its logged iterations after the first."""
    starts, lengths = segment_bounds(reference.n_frames, 50.0, 1.0, 0.25)
    env = EnvConfig(num_envs=args.envs // args.ranks, threads=args.threads, **PATHS["fast"])
    config = TrainConfig(
        iterations=iterations, checkpoint_every=iterations, scoring_starts=1, ranks=args.ranks, env=env
    )
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as folder:
        segments = Segments(starts, lengths, np.zeros(len(starts)))
        job = TrainingJob(robot, reference, segments, config, Path(folder) / "work", None)
        train_in_processes(job, rows.append)
    return statistics.median(row["samples_per_s"] for row in rows[1:])


def _rss_mb() -> float:
    """Current resident set size (Linux)."""
    pages = int(Path("/proc/self/statm").read_text().split()[1])
    return pages * resource.getpagesize() / 2**20


if __name__ == "__main__":
    main()
