"""The policy as ONNX (`policy.onnx`) for runtimes without torch, with its deploy facts as metadata.

Same input and output as `policy.pt`: (batch, observation_size) float32 observations in, (batch,
num_actions) mean actions out. The metadata repeats what a deploy loop needs from `policy.json`
as `metadata_props` (comma-separated values, the way mjlab labels its exported policies), so an
ONNX file alone says which joint each output drives, with what gains and action semantics.
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import torch

from rd_pipeline.files import write_bytes_whole
from rd_pipeline.policy_spec import ONNX_FILE, PolicySpec

__all__ = ["ONNX_FILE", "export_onnx", "onnx_metadata"]

OPSET = 18
"""ONNX opset the policy is written with."""


def onnx_metadata(spec: PolicySpec) -> dict[str, str]:
    """Deploy facts of `policy.json` as ONNX metadata strings."""
    joints = spec.get("joints")
    policy = joints["policy"]
    actuated = joints["actuated"]
    by_policy = [actuated.index(name) for name in policy]
    numbers = lambda values: ",".join(repr(float(v)) for v in values)
    return {
        "robot": spec.get("robot"),
        "joint_names": ",".join(policy),
        "joint_stiffness": numbers(joints["kp"][i] for i in by_policy),
        "joint_damping": numbers(joints["kd"][i] for i in by_policy),
        "default_joint_pos": numbers(joints["default_pos"][i] for i in by_policy),
        "action_names": ",".join(spec.get("action.outputs")),
        "action_semantics": ",".join(spec.get("action.semantics")),
        "action_scale": repr(float(spec.get("action.scale"))),
        "action_clip": repr(float(spec.get("action.clip"))),
        "observation_names": ",".join(term["name"] for term in spec.get("observation.terms")),
        "observation_history": str(spec.get("observation.history")),
        "control_hz": repr(float(spec.get("rates.control_hz"))),
        "reference_key": spec.get("reference.key"),
    }


def export_onnx(module: torch.nn.Module, observation_size: int, spec: PolicySpec, path: Path) -> None:
    """Write `module` ((B, observation_size) -> (B, num_actions)) as ONNX with a free batch size."""
    import onnx

    probe = torch.zeros(2, observation_size)
    batch = torch.export.Dim("batch", min=1)
    with _quiet_exporter():
        program = torch.onnx.export(
            module.eval(),
            (probe,),
            dynamo=True,
            opset_version=OPSET,
            input_names=["obs"],
            output_names=["actions"],
            dynamic_shapes=({0: batch},),
            verbose=False,
        )
    assert program is not None  # the dynamo exporter always returns its program
    model = program.model_proto
    for key, value in onnx_metadata(spec).items():
        entry = model.metadata_props.add()
        entry.key = key
        entry.value = value
    onnx.checker.check_model(model)
    write_bytes_whole(path, model.SerializeToString())


@contextmanager
def _quiet_exporter() -> Iterator[None]:
    """The exporter logs that torchvision's operators are not installed (a policy uses none) and
    pytree FutureWarnings of its own: nothing a user of the exported file can act on."""
    registration = logging.getLogger("torch.onnx._internal.exporter._registration")
    level = registration.level
    registration.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            yield
    finally:
        registration.setLevel(level)
