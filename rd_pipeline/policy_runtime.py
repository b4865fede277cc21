"""The exported policy files run as a deploy loop would run them: TorchScript on torch, ONNX on
onnxruntime, both as numpy (R, observation_size) -> (R, num_actions) functions."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from rd_pipeline.policy_spec import ONNX_FILE, POLICY_FILE

RUNTIMES = ("torchscript", "onnx")

Policy = Callable[[np.ndarray], np.ndarray]
"""(R, observation_size) float32 -> (R, num_actions)."""


class OnnxPolicy:
    """`policy.onnx` on onnxruntime (one thread), called like the TorchScript policy on numpy arrays."""

    def __init__(self, path: Path) -> None:
        import onnxruntime  # loaded only when an ONNX policy runs

        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads = 1
        options.inter_op_num_threads = 1
        self.session = onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        self.metadata = self.session.get_modelmeta().custom_metadata_map

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self.session.run(None, {"obs": obs.astype(np.float32)})[0]


def load_runtimes(folder: Path) -> dict[str, Policy]:
    """Both exported files of an export artifact, by runtime name."""
    scripted = torch.jit.load(str(folder / POLICY_FILE))
    return {
        "torchscript": lambda obs: scripted(torch.from_numpy(obs)).numpy(),
        "onnx": OnnxPolicy(folder / ONNX_FILE),
    }
