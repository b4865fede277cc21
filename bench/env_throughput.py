"""Benchmark: environment steps/s with a fixed (zero) policy against raw `mj_step` on the same cores,
and full PPO samples/s including the update.

    python bench/env_throughput.py [--robot g1] [--envs 64] [--threads 2] [--backend cpu|warp]
        [--out bench/results/env_throughput.json]

Raw throughput runs `mj_step` on the environment's own simulation models (one per environment,
domain-randomized), started from copies of the environments' states after each timed block, in the
same number of threads; the ratio compares physics steps per second (env steps x decimation)
measured side by side, interleaved, in one run. With `--backend warp` the raw figure is
`mujoco_warp.step` on the environment's own batched model and data (all worlds at once).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import mujoco
import numpy as np
import torch

from rd_pipeline import paths
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.rl.env import TrackingEnv
from rd_pipeline.rl.env_config import EnvConfig
from rd_pipeline.rl.ppo import PpoConfig, build_ppo
from rd_pipeline.rl.rewards import GROUPS
from rd_pipeline.robots import load_robot
from rd_pipeline.sampling.sampler import SamplerConfig, SegmentSampler
from rd_pipeline.sampling.segments import segment_bounds


def raw_physics_steps_per_s(models: list[mujoco.MjModel], source: list[mujoco.MjData], threads: int,
                            steps: int) -> float:
    """Plain `mj_step` over the environment's own (domain-randomized) models, from copies of the
    environments' current states and controls (the same contacts to solve), in the same threads."""
    envs = len(models)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    datas = []
    for model, data in zip(models, source):
        state = np.empty(mujoco.mj_stateSize(model, spec))
        mujoco.mj_getState(model, data, state, spec)
        copy = mujoco.MjData(model)
        mujoco.mj_setState(model, copy, state, spec)
        mujoco.mj_forward(model, copy)
        datas.append(copy)
    chunks = np.array_split(np.arange(envs), threads)

    def run(chunk: np.ndarray) -> None:
        for _ in range(steps // 10):
            for i in chunk:
                mujoco.mj_step(models[i], datas[i], nstep=10)

    began = time.perf_counter()
    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(run, chunks))
    return envs * steps / (time.perf_counter() - began)


def raw_warp_steps_per_s(backend, steps: int) -> float:
    """`mujoco_warp.step` on the backend's batched model and data, 10 steps per launch (a CUDA graph
    on a GPU, as the environment does), without any read-back."""
    wp, mjw = backend.wp, backend.mjw
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--envs", type=int, default=64)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--backend", choices=("cpu", "warp"), default="cpu")
    parser.add_argument("--device", default="cpu", help="torch device: cpu, or cuda with --backend warp")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path("bench/results/env_throughput.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    robot = load_robot(args.robot)
    reference = import_retargeted_csv(paths.csv_path(args.robot, args.motion), robot, 30.0, 50.0, "cubic",
                                      ContactThresholds()).reference
    starts, lengths = segment_bounds(reference.n_frames, 50.0, 1.0, 0.25)
    sampler = SegmentSampler(SamplerConfig(), torch.ones(len(starts)), seed=0)
    config = EnvConfig(num_envs=args.envs, threads=args.threads, backend=args.backend, device=args.device)
    env = TrackingEnv(robot, reference, sampler, starts, lengths, config, seed=0)
    zero = torch.zeros(args.envs, env.num_actions, device=env.device)
    env_rates, raw_rates = [], []
    for _ in range(args.repeats):  # interleaved, so both see the same machine state
        began = time.perf_counter()
        for _ in range(50):
            env.step(zero)
        env_rates.append(args.envs * 50 * config.decimation / (time.perf_counter() - began))
        raw_rates.append(raw_warp_steps_per_s(env.backend, 500) if args.backend == "warp"
                         else raw_physics_steps_per_s(env.backend.models, env.backend.datas, args.threads, 500))
    ppo = build_ppo(env.get_observations(), args.envs, env.num_actions, len(GROUPS), PpoConfig(), args.device)
    obs = env.get_observations()
    began = time.perf_counter()
    iterations = 3
    for _ in range(iterations):
        with torch.inference_mode():
            for _ in range(ppo.storage.num_transitions_per_env):
                actions = ppo.act(obs)
                obs, reward, dones, extras = env.step(actions)
                ppo.process_env_step(obs, reward, dones, extras)
            ppo.compute_returns(obs)
        ppo.update()
    ppo_rate = iterations * ppo.storage.num_transitions_per_env * args.envs / (time.perf_counter() - began)
    env_median, raw_median = statistics.median(env_rates), statistics.median(raw_rates)
    result = {
        "robot": args.robot, "envs": args.envs, "threads": args.threads, "backend": args.backend,
        "env_steps_per_s": round(env_median / config.decimation, 1),
        "env_physics_steps_per_s": round(env_median, 1), "raw_mj_step_per_s": round(raw_median, 1),
        "ratio": round(env_median / raw_median, 3), "ratio_target": 0.7,
        "ppo_samples_per_s_including_update": round(ppo_rate, 1),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
