"""`export`: the trained actor -> `policy.pt` (TorchScript) + `policy.json` (everything a deploy loop needs)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rd_pipeline.artifacts.stage import Stage, StageContext
from rd_pipeline.errors import PipelineError
from rd_pipeline.robots.assets import model_files

REFERENCE_STAGES = ("retarget", "import")


@dataclass(frozen=True)
class ExportConfig:
    """Which checkpoint goes to the robot."""

    checkpoint: int = 0
    """Training iteration of the checkpoint to export (0: the one `train` scored best: the longest
    start-zero survival on nominal physics, then the highest completion, then the latest)."""


def _run(ctx: StageContext) -> dict[str, Any]:
    import numpy as np
    import torch
    from tensordict import TensorDict

    from rd_pipeline.evaluation.runtimes import OnnxPolicy
    from rd_pipeline.export.exporter import build_policy_spec, load_actor, script_actor
    from rd_pipeline.export.onnx_policy import ONNX_FILE, export_onnx
    from rd_pipeline.policy_spec import POLICY_FILE, SPEC_FILE, load_policy_spec
    from rd_pipeline.rl.training_log import checkpoints_by_iteration
    from rd_pipeline.robots import load_robot

    train = ctx.upstream["policy"]
    manifest = train.manifest
    checkpoints = checkpoints_by_iteration(train.path)
    if not checkpoints:
        raise PipelineError(f"{train.path}: the training artifact has no checkpoints")
    iteration = ctx.params.checkpoint or train.manifest["metrics"]["best_checkpoint"]
    if iteration not in checkpoints:
        raise PipelineError(f"export.checkpoint {iteration}: no such checkpoint (have {sorted(checkpoints)})")
    metrics, params = manifest["metrics"], manifest["params"]
    actor = load_actor(
        checkpoints[iteration], metrics["observation_size"], metrics["num_actions"], list(params["ppo"]["hidden_dims"])
    )
    scripted = script_actor(actor)
    scripted.save(str(ctx.out_dir / POLICY_FILE))
    reference_stage = next(s for s in REFERENCE_STAGES if s in manifest["upstream"])
    spec = build_policy_spec(
        load_robot(ctx.robot_name),
        params["env"],
        metrics["num_actions"],
        reference_stage,
        manifest["upstream"][reference_stage],
        tuple(metrics["clip_frames"]),
    )
    spec.save(ctx.out_dir / SPEC_FILE)
    load_policy_spec(ctx.out_dir / SPEC_FILE)  # what we wrote must pass the deploy-side check
    export_onnx(actor.as_jit().cpu(), metrics["observation_size"], spec, ctx.out_dir / ONNX_FILE)
    probe = torch.zeros(1, metrics["observation_size"])
    with torch.inference_mode():
        expected = actor(TensorDict({"policy": probe}, batch_size=[1]), stochastic_output=False)
        gap = float((scripted(probe) - expected).abs().max())
        # Normalized observations are O(1); a spread of 3 covers what a rollout feeds the policy.
        noise = torch.from_numpy(np.random.default_rng(0).normal(0.0, 3.0, (256, metrics["observation_size"])))
        noise = noise.float()
        onnx_gap = float(np.abs(OnnxPolicy(ctx.out_dir / ONNX_FILE)(noise.numpy()) - scripted(noise).numpy()).max())
    return {
        "checkpoint_iteration": iteration,
        "observation_size": metrics["observation_size"],
        "num_actions": metrics["num_actions"],
        "action_mode": spec.get("action.mode"),
        "reference_key": spec.get("reference.key"),
        "max_abs_diff_on_zero_observation": gap,
        "onnx_max_abs_diff_vs_torchscript": onnx_gap,
    }


STAGE = Stage(
    name="export",
    version=4,
    description="trained actor -> policy.pt (TorchScript) + policy.json (gains, scales, mask, obs layout, rates)",
    params=ExportConfig,
    provides="deployable_policy",
    run=_run,
    inputs=lambda robot, motion: model_files(robot),
    requires=("policy",),
    headline=("num_actions", "action_mode"),
)
