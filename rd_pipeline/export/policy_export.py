"""Exporting a trained checkpoint: the TorchScript actor, `policy.json`, the ONNX twin, and how
closely each file reproduces the training actor."""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rsl_rl.models import MLPModel
from tensordict import TensorDict

from rd_pipeline.errors import PipelineError
from rd_pipeline.export.exporter import build_policy_spec, load_actor, script_actor
from rd_pipeline.export.onnx_policy import export_onnx
from rd_pipeline.files import write_bytes_whole
from rd_pipeline.policy_runtime import OnnxPolicy
from rd_pipeline.policy_spec import ONNX_FILE, POLICY_FILE, SPEC_FILE, load_policy_spec
from rd_pipeline.robots import Robot
from rd_pipeline.training.config import TrainConfig
from rd_pipeline.training.log import checkpoints_by_iteration


@dataclass(frozen=True)
class TrainedPolicy:
    """What export reads of a train artifact."""

    folder: Path
    """The artifact folder (its checkpoints)."""
    config: TrainConfig
    """The training config, rebuilt typed from the manifest."""
    observation_size: int
    """Actor input size."""
    num_actions: int
    """Actor output size."""
    clip_frames: tuple[int, int]
    """[start, end) reference frames it trained on."""
    reference_stage: str
    """The stage that made its reference (`retarget` or `import`)."""
    reference_key: str
    """That reference artifact's key."""


def export_policy(trained: TrainedPolicy, robot: Robot, iteration: int, rule: str, out_dir: Path) -> dict[str, Any]:
    """Write `policy.pt`, `policy.json` and `policy.onnx` of the checkpoint saved after `iteration`
    iterations, chosen by `rule` (in words, for the reports), into `out_dir`; returns the export's
    metrics."""
    checkpoints = checkpoints_by_iteration(trained.folder)
    if not checkpoints:
        raise PipelineError(f"{trained.folder}: the training artifact has no checkpoints")
    if iteration not in checkpoints:
        raise PipelineError(f"export.checkpoint {iteration}: no such checkpoint (have {sorted(checkpoints)})")
    hidden = list(trained.config.learner.hidden_dims)
    actor = load_actor(checkpoints[iteration], trained.observation_size, trained.num_actions, hidden)
    scripted = script_actor(actor)
    # Through memory: torch's file writer turns a full disk into a RuntimeError.
    buffer = io.BytesIO()
    torch.jit.save(scripted, buffer)
    write_bytes_whole(out_dir / POLICY_FILE, buffer.getvalue())
    spec = build_policy_spec(
        robot,
        trained.config.env,
        trained.num_actions,
        trained.reference_stage,
        trained.reference_key,
        trained.clip_frames,
    )
    spec.data["checkpoint"] = {"iteration": iteration, "rule": rule}
    spec.save(out_dir / SPEC_FILE)
    load_policy_spec(out_dir / SPEC_FILE)  # what we wrote must pass the deploy-side check
    export_onnx(actor.as_jit().cpu(), trained.observation_size, spec, out_dir / ONNX_FILE)
    gap, onnx_gap = _file_gaps(actor, scripted, out_dir / ONNX_FILE, trained.observation_size)
    return {
        "checkpoint_iteration": iteration,
        "checkpoint_rule": rule,
        "observation_size": trained.observation_size,
        "num_actions": trained.num_actions,
        "action_mode": spec.get("action.mode"),
        "reference_key": spec.get("reference.key"),
        "max_abs_diff_on_zero_observation": gap,
        "onnx_max_abs_diff_vs_torchscript": onnx_gap,
    }


def _file_gaps(actor: MLPModel, scripted: torch.jit.ScriptModule, onnx: Path, size: int) -> tuple[float, float]:
    """Largest |TorchScript - actor| on a zero observation, and |ONNX - TorchScript| on noise."""
    probe = torch.zeros(1, size)
    with torch.inference_mode():
        expected = actor(TensorDict({"policy": probe}, batch_size=[1]), stochastic_output=False)
        gap = float((scripted(probe) - expected).abs().max())
        # Normalized observations are O(1); a spread of 3 covers what a rollout feeds the policy.
        noise = torch.from_numpy(np.random.default_rng(0).normal(0.0, 3.0, (256, size)))
        noise = noise.float()
        onnx_gap = float(np.abs(OnnxPolicy(onnx)(noise.numpy()) - scripted(noise).numpy()).max())
    return gap, onnx_gap
