"""Sim2sim validation of an exported policy: the SPEC protocol run on the full-mesh model from the
exported files alone, beside the zero-action baseline, reduced to a typed report."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import torch

from rd_pipeline.env.sim_model import pd_simulation_model
from rd_pipeline.errors import PipelineError
from rd_pipeline.evaluation.deploy import reference_baseline_spec
from rd_pipeline.evaluation.disturbances import Disturbances, RandomizedPhysics
from rd_pipeline.evaluation.metrics import drift, per_second, summarize, t_interval, tracked_pct
from rd_pipeline.evaluation.protocol import Protocol
from rd_pipeline.evaluation.report import CONTROLLERS
from rd_pipeline.evaluation.sim2sim import BodySets, Rollout, reference_states, run_rollouts
from rd_pipeline.evaluation.validation_config import ValidationConfig
from rd_pipeline.evaluation.validation_report import ValidationReport
from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
from rd_pipeline.policy_runtime import Policy, load_runtimes
from rd_pipeline.policy_spec import SPEC_FILE, PolicySpec, load_policy_spec
from rd_pipeline.robots import Robot
from rd_pipeline.robots.assets import asset_path
from rd_pipeline.viz.render import Scene, render_pictures
from rd_pipeline.viz.render_config import RenderConfig
from rd_pipeline.viz.tracked import TrackedRollout


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
    model: mujoco.MjModel
    """The nominal deploy model the rollouts ran on."""
    root_body: str


def rollout_pictures(validation: Validation, clip: ReferenceClip, look: RenderConfig, out_dir: Path) -> dict[str, str]:
    """Render the policy's nominal start-zero rollout beside its reference into `out_dir` (see
    `render_pictures`); the report's `pictures` entry."""
    details = validation.report.details
    title = f"{details['robot']} {details['motion']}, policy {details['policy_key']}, nominal start-zero rollout"
    return render_pictures(validation.model, _rollout_scene(validation, clip, title), look, out_dir)


def recorded_rollout(validation: Validation, clip: ReferenceClip) -> TrackedRollout:
    """The policy's nominal start-zero rollout as the recordings show it: poses, errors, its end."""
    tracked = validation.tracked
    assert tracked.body_pos is not None and tracked.body_quat is not None  # the first rollout keeps its poses
    return TrackedRollout(
        body_pos=tracked.body_pos,
        body_quat=tracked.body_quat,
        first_frame=clip.start_frame + tracked.start_frame,
        fps=clip.motion.fps,
        body_error_m=tracked.errors["E_mpbpe"] / 1000.0,
        joint_error_rad=tracked.errors["E_mpjpe"] / 1000.0,
        ended_by=tracked.ended_by,
    )


def _rollout_scene(validation: Validation, clip: ReferenceClip, title: str) -> Scene:
    """The pictures' scene: the policy's nominal start-zero rollout and its reference."""
    tracked = validation.tracked
    assert tracked.qpos is not None  # the first rollout keeps its poses
    frames = np.arange(tracked.start_frame, clip.motion.n_frames)
    root = clip.motion.body_names.index(validation.root_body)
    reference, _ = reference_states(validation.model, clip.motion, frames, root)
    control_hz = validation.report.details["rates"]["control_hz"]
    return Scene(title, tracked.qpos, reference, control_hz, tracked.ended_by)


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
    """Run every protocol (nominal, randomized per seed, other physics) from every fixed-grid start
    with the policy and zero action; `advance` is called after each batch of rollouts."""
    spec = load_exported_spec(exported, clip.key)
    grid = _Grid.build(robot, spec, exported, clip, config)
    nominal = {}
    first = {}
    protocols: dict[str, dict[str, Any]] = {}
    # A small MLP on a few hundred rows: the physics threads want the cores.
    with _torch_threads(1):
        done = {}
        for name in CONTROLLERS:
            done[name] = grid.rollouts(name, [grid.model] * grid.count)
            nominal[name] = _nominal_summary(done[name], grid.control_hz, grid.rng, config.bootstrap_resamples)
            first[name] = done[name][0]
            advance(name)
        protocols["nominal"] = _protocol_summary("training's physics, exact sensors", [done], grid)
        if config.randomized.seeds:
            protocols["randomized"] = _randomized(grid, advance)
        if config.other_physics.enabled:
            protocols["other_physics"] = _other_physics(grid, advance)
        compared, gap = grid.controllers.runtime_gap()
    details = {
        "robot": robot.config.name,
        "motion": motion,
        "policy_key": policy_key,
        "checkpoint": spec.data.get("checkpoint", {}),
        "reference": _reference_details(clip),
        "rates": {
            "control_hz": grid.control_hz,
            "physics_hz": config.protocol.physics_hz,
            "trained_physics_hz": spec.get("rates.physics_hz"),
        },
        "protocol": _protocol_details(config, grid.count),
        "nominal": nominal,
        "protocols": protocols,
        "tracking": _tracking_details(first, grid),
        "runtime": {"ran": config.runtime, "observations_compared": compared, "onnx_vs_torchscript_max_abs_diff": gap},
    }
    report = ValidationReport.from_details(details)
    return Validation(report, first["policy"], grid.model, robot.config.root_body)


@dataclass
class _Grid:
    """What every protocol's rollouts share: the controllers, the starts, the checked bodies."""

    spec: PolicySpec
    model: mujoco.MjModel
    controllers: _Controllers
    clip: ReferenceClip
    bodies: BodySets
    starts: np.ndarray
    control_hz: float
    config: ValidationConfig
    root_body: int
    rng: np.random.Generator
    """Draws the drift CI's bootstrap."""

    @classmethod
    def build(
        cls, robot: Robot, spec: PolicySpec, exported: Path, clip: ReferenceClip, config: ValidationConfig
    ) -> _Grid:
        model = deploy_model(spec, config.protocol.physics_hz)
        rc = robot.config
        control_hz = spec.get("rates.control_hz")
        # A rate the policy's cannot divide is refused before any rollout.
        config.protocol.substeps(control_hz)
        if config.other_physics.enabled:
            _other_protocol(config).substeps(control_hz)
        step = max(1, round(config.protocol.grid_s * control_hz))
        return cls(
            spec=spec,
            model=model,
            controllers=_Controllers(exported, spec, config),
            clip=clip,
            bodies=BodySets(rc.root_body, rc.tracking_bodies, rc.termination_bodies, rc.foot_bodies),
            starts=np.arange(0, clip.motion.n_frames - 1, step),
            control_hz=control_hz,
            config=config,
            root_body=model.body(rc.root_body).id,
            rng=np.random.default_rng(config.bootstrap_seed),
        )

    @property
    def count(self) -> int:
        return len(self.starts)

    def rollouts(
        self,
        name: str,
        models: list[mujoco.MjModel],
        protocol: Protocol | None = None,
        disturbances: Disturbances | None = None,
    ) -> list[Rollout]:
        policy = self.controllers.policies[name]
        return run_rollouts(
            self.controllers.specs[name],
            models,
            self.clip.motion,
            policy,
            self.starts,
            self.bodies,
            protocol or self.config.protocol,
            disturbances,
        )


def _randomized(grid: _Grid, advance: Callable[[str], None]) -> dict[str, Any]:
    """Per seed, one grid of rollouts per controller on physics and disturbances drawn from it
    (the same draws for both controllers, as long as both run)."""
    randomized = grid.config.randomized
    joints = grid.spec.get("joints")
    runs: list[dict[str, list[Rollout]]] = []
    effort = np.asarray(joints["effort_limit"])
    for seed in randomized.seeds:
        physics = RandomizedPhysics.draw(grid.model, grid.count, grid.root_body, effort, randomized, seed)
        run = {}
        for name in CONTROLLERS:
            disturbances = Disturbances.start(physics, joints["actuated"], 1.0 / grid.control_hz, randomized, seed)
            run[name] = grid.rollouts(name, physics.models, disturbances=disturbances)
            advance(f"{name} randomized seed {seed}")
        runs.append(run)
    drawn = "the paper's domain randomization (mass, COM, friction, PD gains, RFI, delay 0-2 steps, pushes)"
    summary = _protocol_summary(f"{drawn} and sensor noise", runs, grid)
    return {"seeds": list(randomized.seeds), **summary}


def _other_protocol(config: ValidationConfig) -> Protocol:
    return dataclasses.replace(config.protocol, physics_hz=config.other_physics.physics_hz)


def _other_physics(grid: _Grid, advance: Callable[[str], None]) -> dict[str, Any]:
    other = grid.config.other_physics
    model = deploy_model(grid.spec, other.physics_hz)
    model.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{other.integrator.upper()}")
    model.opt.cone = getattr(mujoco.mjtCone, f"mjCONE_{other.cone.upper()}")
    run = {}
    for name in CONTROLLERS:
        run[name] = grid.rollouts(name, [model] * grid.count, _other_protocol(grid.config))
        advance(f"{name} other physics")
    return _protocol_summary(other.describe(), [run], grid)


def _protocol_summary(physics: str, runs: list[dict[str, list[Rollout]]], grid: _Grid) -> dict[str, Any]:
    """Per controller, the protocol's figures with 95% Student-t CIs: over the runs (seeds) where
    there are several, else over the grid's starts (start-zero then has none)."""
    out: dict[str, Any] = {"physics": physics, "runs": len(runs), "rollouts_per_run": grid.count}
    for name in CONTROLLERS:
        figures = [_run_figures(run[name], grid) for run in runs]
        if len(runs) > 1:
            out[name] = {key: t_interval([f[key] for f in figures]) for key in figures[0] if key != "per_start"}
            continue
        only = figures[0]
        out[name] = {key: t_interval(only["per_start"][key]) for key in only["per_start"]}
        out[name]["start_zero_s"] = t_interval([only["start_zero_s"]])
        out[name] |= {key: t_interval([only[key]]) for key in ("E_mpjpe", "E_mpbpe")}
    return out


def _run_figures(rollouts: list[Rollout], grid: _Grid) -> dict[str, Any]:
    """One grid's figures, and per start the ones that average into them (each a plain mean over
    the starts, so one run's CI over its starts and several runs' CI over seeds are of one figure)."""
    tolerance = grid.config.tracking
    summary = summarize(rollouts, grid.control_hz)
    survival = [r.steps / grid.control_hz for r in rollouts]
    completed = [100.0 * r.completed for r in rollouts]
    tracked = [tracked_pct([r], tolerance) for r in rollouts]
    return {
        "start_zero_s": survival[0],
        "completion_pct": summary["completion_pct"],
        "mean_survival_s": summary["mean_survival_s"],
        "tracked_pct": round(float(np.mean(tracked)), 2),
        "E_mpjpe": summary["E_mpjpe"],
        "E_mpbpe": summary["E_mpbpe"],
        "per_start": {"completion_pct": completed, "mean_survival_s": survival, "tracked_pct": tracked},
    }


def _tracking_details(first: dict[str, Rollout], grid: _Grid) -> dict[str, Any]:
    """Nominal start-zero rollouts, second by second, and the tolerances that count a step tracked."""
    tolerance = grid.config.tracking
    return {
        "tolerance": {"joint_rad": tolerance.joint_rad, "body_m": tolerance.body_m},
        "start_zero_tracked_pct": {name: tracked_pct([first[name]], tolerance) for name in CONTROLLERS},
        "per_second": {name: per_second(first[name], grid.control_hz, tolerance) for name in CONTROLLERS},
    }


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
