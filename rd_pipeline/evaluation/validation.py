"""Sim2sim validation of an exported policy: the SPEC protocol run on the full-mesh model from the
exported files alone, beside the zero-action baseline, reduced to a typed report."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch

from rd_pipeline.errors import PipelineError
from rd_pipeline.evaluation.deploy import reference_baseline_spec
from rd_pipeline.evaluation.metrics import drift, summarize, t_interval
from rd_pipeline.evaluation.report import CONTROLLERS
from rd_pipeline.evaluation.sim2sim import BodySets, Rollout, randomized_models, run_rollouts
from rd_pipeline.evaluation.validation_config import ValidationConfig
from rd_pipeline.evaluation.validation_report import ValidationReport
from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
from rd_pipeline.policy_runtime import Policy, load_runtimes
from rd_pipeline.policy_spec import SPEC_FILE, PolicySpec, load_policy_spec
from rd_pipeline.rl.sim_model import pd_simulation_model
from rd_pipeline.robots import Robot
from rd_pipeline.robots.assets import asset_path

RANDOMIZED_METRICS = ("completion_pct", "mean_survival_s", "E_g_mpbpe", "E_mpjpe")


@dataclass(frozen=True)
class ReferenceClip:
    """The part of a reference artifact a policy was trained on."""

    stage: str
    """The stage that made the reference (`retarget` or `import`)."""
    key: str
    """Its artifact key."""
    motion: ReferenceMotion
    """The clip's frames."""
    start_frame: int
    """First frame of the clip in the whole reference."""
    end_frame: int
    """One past its last frame."""


@dataclass(frozen=True)
class Validation:
    """A finished validation: its report and the policy's start-zero rollout (for the recording)."""

    report: ValidationReport
    tracked: Rollout


def reference_clip(spec: PolicySpec, stage: str, key: str, folder: Path) -> ReferenceClip:
    """The frames of the reference artifact in `folder` (made by `stage`, key `key`) that the
    exported policy of `spec` was trained on."""
    start = spec.get("reference.start_frame")
    end = spec.get("reference.end_frame")
    motion = ReferenceMotion.load(folder / REFERENCE_FILE).frames(start, end)
    return ReferenceClip(stage, key, motion, start, end)


def load_exported_spec(folder: Path, reference_key: str) -> PolicySpec:
    """`policy.json` of an export artifact, checked to belong to the reference it is validated on."""
    spec = load_policy_spec(folder / SPEC_FILE)
    if spec.get("reference.key") != reference_key:
        raise PipelineError(
            f"{folder / SPEC_FILE}: the policy was trained on reference {spec.get('reference.key')}, not {reference_key}"
        )
    return spec


def deploy_model(spec: PolicySpec, physics_hz: float) -> mujoco.MjModel:
    """The robot's full-mesh model with the exported PD gains, stepping at `physics_hz`."""
    joints = spec.get("joints")
    return pd_simulation_model(
        asset_path(spec.get("mjcf")),
        joints["actuated"],
        np.array(joints["kp"]),
        np.array(joints["kd"]),
        np.array(joints["effort_limit"]),
        1.0 / physics_hz,
    )


class _Controllers:
    """The policy (in the chosen runtime, its first observations recorded) and zero action."""

    def __init__(self, folder: Path, spec: PolicySpec, config: ValidationConfig) -> None:
        self.runtimes = load_runtimes(folder)
        self.config = config
        self.recorded: list[np.ndarray] = []
        joints = len(spec.get("joints.policy"))
        self.specs = {"policy": spec, "zero_action": reference_baseline_spec(spec)}
        self.policies: dict[str, Policy] = {
            "policy": self._policy,
            "zero_action": lambda obs: np.zeros((len(obs), joints)),
        }

    def _policy(self, obs: np.ndarray) -> np.ndarray:
        if sum(len(o) for o in self.recorded) < self.config.recorded_observations:
            self.recorded.append(obs.copy())
        with torch.inference_mode():
            return self.runtimes[self.config.runtime](obs).astype(np.float64)

    def runtime_gap(self) -> tuple[int, float]:
        """(observations compared, largest |ONNX - TorchScript|) on the recorded observations."""
        observations = np.concatenate(self.recorded)[: self.config.recorded_observations]
        with torch.inference_mode():
            gap = np.abs(self.runtimes["onnx"](observations) - self.runtimes["torchscript"](observations))
        return len(observations), float(gap.max())


def validate_policy(
    robot: Robot,
    motion: str,
    exported: Path,
    policy_key: str,
    clip: ReferenceClip,
    config: ValidationConfig,
    advance: Callable[[str], None] = lambda status: None,
) -> Validation:
    """Run the protocol from every fixed-grid start with the policy and zero action, on nominal and
    (per seed) randomized physics; `advance` is called after each batch of rollouts."""
    spec = load_exported_spec(exported, clip.key)
    model = deploy_model(spec, config.protocol.physics_hz)
    controllers = _Controllers(exported, spec, config)
    rc = robot.config
    bodies = BodySets(rc.root_body, rc.tracking_bodies, rc.termination_bodies, rc.foot_bodies)
    control_hz = spec.get("rates.control_hz")
    config.protocol.substeps(control_hz)  # a rate the policy's cannot divide is refused before any rollout
    step = max(1, round(config.protocol.grid_s * control_hz))
    starts = np.arange(0, clip.motion.n_frames - 1, step)

    def rollouts(name: str, models: list[mujoco.MjModel]) -> list[Rollout]:
        policy = controllers.policies[name]
        return run_rollouts(controllers.specs[name], models, clip.motion, policy, starts, bodies, config.protocol)

    rng = np.random.default_rng(config.bootstrap_seed)
    nominal = {}
    first = {}
    # A small MLP on a few hundred rows: the physics threads want the cores.
    with _torch_threads(1):
        for name in CONTROLLERS:
            done = rollouts(name, [model] * len(starts))
            nominal[name] = _nominal_summary(done, control_hz, rng, config.bootstrap_resamples)
            first[name] = done[0]
            advance(name)
        randomized = _randomized_summary(model, len(starts), config.randomized_seeds, rollouts, control_hz, advance)
        compared, gap = controllers.runtime_gap()
    details = {
        "robot": rc.name,
        "motion": motion,
        "policy_key": policy_key,
        "reference": _reference_details(clip),
        "rates": {
            "control_hz": control_hz,
            "physics_hz": config.protocol.physics_hz,
            "trained_physics_hz": spec.get("rates.physics_hz"),
        },
        "protocol": _protocol_details(config, len(starts)),
        "nominal": nominal,
        "runtime": {"ran": config.runtime, "observations_compared": compared, "onnx_vs_torchscript_max_abs_diff": gap},
        **({"randomized": randomized} if randomized else {}),
    }
    return Validation(ValidationReport.from_details(details), first["policy"])


@contextmanager
def _torch_threads(count: int) -> Iterator[None]:
    """Torch on `count` threads within the block, and on as many as before it after."""
    before = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _reference_details(clip: ReferenceClip) -> dict[str, Any]:
    return {
        "stage": clip.stage,
        "key": clip.key,
        "start_frame": clip.start_frame,
        "end_frame": clip.end_frame,
        "duration_s": clip.motion.duration_s,
    }


def _protocol_details(config: ValidationConfig, starts: int) -> dict[str, Any]:
    return {
        "grid_s": config.protocol.grid_s,
        "starts": starts,
        "motion_far_m": config.protocol.motion_far_m,
        "orientation_limit_rad": config.protocol.orientation_limit_rad,
    }


def _nominal_summary(
    rollouts: list[Rollout], control_hz: float, rng: np.random.Generator, resamples: int
) -> dict[str, Any]:
    return {
        "fixed_grid": summarize(rollouts, control_hz),
        "start_zero": summarize(rollouts[:1], control_hz),
        "drift": drift(rollouts, rng, resamples),
        "per_start": {
            "start_s": [r.start_frame / control_hz for r in rollouts],
            "survival_s": [r.steps / control_hz for r in rollouts],
            "most_s": [r.remaining_steps / control_hz for r in rollouts],
            "ended_by": [r.ended_by for r in rollouts],
        },
    }


def _randomized_summary(
    model: mujoco.MjModel,
    count: int,
    seeds: tuple[int, ...],
    rollouts: Callable[[str, list[mujoco.MjModel]], list[Rollout]],
    control_hz: float,
    advance: Callable[[str], None],
) -> dict[str, Any]:
    """Per controller, each randomized metric reduced over the seeds (mean and Student-t CI)."""
    if not seeds:
        return {}
    per_seed: dict[str, list[dict]] = {name: [] for name in CONTROLLERS}
    for seed in seeds:
        models = randomized_models(model, count, np.random.default_rng(seed))
        for name in CONTROLLERS:
            per_seed[name].append(summarize(rollouts(name, models), control_hz))
            advance(f"{name} seed {seed}")
    reduced = {
        name: {metric: t_interval([s[metric] for s in per_seed[name]]) for metric in RANDOMIZED_METRICS}
        for name in CONTROLLERS
    }
    return {"seeds": list(seeds), **reduced}
