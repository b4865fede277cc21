"""`validate`: exported policy + reference -> MuJoCo sim2sim report (policy beside the zero-action baseline)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from rd_pipeline.artifacts.stage import Stage, StageContext
from rd_pipeline.errors import PipelineError
from rd_pipeline.evaluation.protocol import Protocol
from rd_pipeline.params import require_positive
from rd_pipeline.robots.assets import model_files

RECORDING_FILE = "sim2sim.rrd"


@dataclass(frozen=True)
class ValidateParams:
    """The evaluation protocol."""

    protocol: Protocol = Protocol()
    """Start grid, failure thresholds, threads."""
    randomized_seeds: tuple[int, ...] = ()
    """Also evaluate on randomized physics, once per seed (empty: nominal only)."""
    bootstrap_seed: int = 0
    """Seeds the bootstrap of the drift CI."""
    recorded_observations: int = 2000
    """Observations of the policy's rollouts kept to compare the two runtimes on."""
    runtime: Literal["torchscript", "onnx"] = "torchscript"
    """Which exported file runs the loop: `policy.pt` on torch or `policy.onnx` on onnxruntime; the
    other one is checked against it on the observations the loop recorded."""

    def __post_init__(self) -> None:
        require_positive(self, "recorded_observations")


def _run(ctx: StageContext) -> dict[str, Any]:
    import numpy as np
    import torch

    from rd_pipeline.evaluation.deploy import reference_baseline_spec
    from rd_pipeline.evaluation.metrics import drift, summarize, t_interval
    from rd_pipeline.evaluation.report import CONTROLLERS, plot_report, write_json, write_markdown
    from rd_pipeline.evaluation.sim2sim import BodySets, randomized_models, run_rollouts
    from rd_pipeline.export.onnx_policy import ONNX_FILE, OnnxPolicy
    from rd_pipeline.export.policy_spec import POLICY_FILE, SPEC_FILE, load_policy_spec
    from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
    from rd_pipeline.rl.sim_model import pd_simulation_model
    from rd_pipeline.robots import load_robot
    from rd_pipeline.robots.assets import asset_path
    from rd_pipeline.viz.recording import TRACKED_FILE, record_tracking, save_tracked

    p: ValidateParams = ctx.params
    exported, reference_ref = ctx.upstream["deployable_policy"], ctx.upstream["reference"]
    spec = load_policy_spec(exported.path / SPEC_FILE)
    if spec.get("reference.key") != reference_ref.key:
        raise PipelineError(
            f"{exported.path / SPEC_FILE}: the policy was trained on reference {spec.get('reference.key')}, "
            f"not {reference_ref.key}"
        )
    start, end = spec.get("reference.start_frame"), spec.get("reference.end_frame")
    reference = ReferenceMotion.load(reference_ref.path / REFERENCE_FILE).frames(start, end)
    joints = spec.get("joints")
    model = pd_simulation_model(
        asset_path(spec.get("mjcf")),
        joints["actuated"],
        np.array(joints["kp"]),
        np.array(joints["kd"]),
        np.array(joints["effort_limit"]),
        1.0 / spec.get("rates.physics_hz"),
    )
    scripted = torch.jit.load(str(exported.path / POLICY_FILE))
    torch.set_num_threads(1)  # a small MLP on a few hundred rows; the physics threads want the cores
    runtimes = {
        "torchscript": lambda obs: scripted(torch.from_numpy(obs)).numpy(),
        "onnx": OnnxPolicy(exported.path / ONNX_FILE),
    }
    recorded: list[np.ndarray] = []

    def policy(obs: np.ndarray) -> np.ndarray:
        if sum(len(o) for o in recorded) < p.recorded_observations:
            recorded.append(obs.copy())
        with torch.inference_mode():
            return runtimes[p.runtime](obs).astype(np.float64)

    specs = {"policy": spec, "zero_action": reference_baseline_spec(spec)}
    joints = len(spec.get("joints.policy"))
    controllers = {"policy": policy, "zero_action": lambda obs: np.zeros((len(obs), joints))}
    config = load_robot(ctx.robot).config
    bodies = BodySets(config.root_body, config.tracking_bodies, config.termination_bodies, config.foot_bodies)
    control_hz = spec.get("rates.control_hz")
    starts = np.arange(0, reference.n_frames - 1, max(1, round(p.protocol.grid_s * control_hz)))
    rng = np.random.default_rng(p.bootstrap_seed)

    nominal, first = {}, {}
    with ctx.progress(len(CONTROLLERS) * (1 + len(p.randomized_seeds)), "sim2sim rollouts") as advance:
        for name in CONTROLLERS:
            rollouts = run_rollouts(
                specs[name], [model] * len(starts), reference, controllers[name], starts, bodies, p.protocol
            )
            nominal[name] = {
                "fixed_grid": summarize(rollouts, control_hz),
                "start_zero": summarize(rollouts[:1], control_hz),
                "drift": drift(rollouts, rng),
                "per_start": {
                    "start_s": [r.start_frame / control_hz for r in rollouts],
                    "survival_s": [r.steps / control_hz for r in rollouts],
                },
            }
            first[name] = rollouts[0]
            advance(name)
        randomized: dict[str, Any] = {}
        if p.randomized_seeds:
            per_seed: dict[str, list[dict]] = {name: [] for name in CONTROLLERS}
            for seed in p.randomized_seeds:
                models = randomized_models(model, len(starts), np.random.default_rng(seed))
                for name in CONTROLLERS:
                    rollouts = run_rollouts(
                        specs[name], models, reference, controllers[name], starts, bodies, p.protocol
                    )
                    per_seed[name].append(summarize(rollouts, control_hz))
                    advance(f"{name} seed {seed}")
            randomized = {
                "seeds": list(p.randomized_seeds),
                **{
                    name: {
                        m: t_interval([s[m] for s in per_seed[name]])
                        for m in ("completion_pct", "mean_survival_s", "E_g_mpbpe", "E_mpjpe")
                    }
                    for name in CONTROLLERS
                },
            }

    observations = np.concatenate(recorded)[: p.recorded_observations]
    with torch.inference_mode():
        runtime_gap = float(np.abs(runtimes["onnx"](observations) - runtimes["torchscript"](observations)).max())
    report = {
        "robot": ctx.robot,
        "motion": ctx.motion,
        "policy_key": exported.key,
        "reference": {
            "stage": reference_ref.stage,
            "key": reference_ref.key,
            "start_frame": start,
            "end_frame": end,
            "duration_s": reference.duration_s,
        },
        "rates": spec.get("rates"),
        "protocol": {
            "grid_s": p.protocol.grid_s,
            "starts": len(starts),
            "motion_far_m": p.protocol.motion_far_m,
            "orientation_limit_rad": p.protocol.orientation_limit_rad,
        },
        "nominal": nominal,
        "runtime": {
            "ran": p.runtime,
            "observations_compared": len(observations),
            "onnx_vs_torchscript_max_abs_diff": runtime_gap,
        },
        **({"randomized": randomized} if randomized else {}),
    }
    write_json(report, ctx.out_dir)
    write_markdown(report, ctx.out_dir)
    plot_report(report, ctx.out_dir)
    tracked = first["policy"]
    save_tracked(ctx.out_dir / TRACKED_FILE, tracked.body_pos, tracked.body_quat, start, reference.fps)
    record_tracking(
        load_robot(ctx.robot).model,
        reference,
        ctx.out_dir / TRACKED_FILE,
        f"{ctx.robot}_{ctx.motion}_sim2sim",
        ctx.out_dir / RECORDING_FILE,
        first_frame=start,
    )
    zero, pol = nominal["zero_action"], nominal["policy"]
    return {
        "start_zero_survival_s": pol["start_zero"]["mean_survival_s"],
        "zero_action_start_zero_survival_s": zero["start_zero"]["mean_survival_s"],
        "completion_pct": pol["fixed_grid"]["completion_pct"],
        "mean_survival_s": pol["fixed_grid"]["mean_survival_s"],
        "zero_action_mean_survival_s": zero["fixed_grid"]["mean_survival_s"],
        "E_g_mpbpe": pol["fixed_grid"]["E_g_mpbpe"],
        "E_mpjpe": pol["fixed_grid"]["E_mpjpe"],
        "runtime": p.runtime,
        "onnx_vs_torchscript_max_abs_diff": runtime_gap,
    }


STAGE = Stage(
    name="validate",
    version=4,
    description="exported policy + reference -> sim2sim report (report.json/md, plots, .rrd) beside zero-action",
    params=ValidateParams,
    provides="validation_report",
    run=_run,
    inputs=lambda robot, motion: model_files(robot),
    requires=("deployable_policy", "reference"),
    headline=("start_zero_survival_s", "zero_action_start_zero_survival_s", "completion_pct", "E_g_mpbpe"),
    report="report.md",
)
