"""What a validation is configured by (the `validate` stage's params); light, so planning a run
loads neither torch nor MuJoCo."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from rd_pipeline.evaluation.protocol import Protocol
from rd_pipeline.params import require_positive


@dataclass(frozen=True)
class ValidationConfig:
    """The evaluation protocol."""

    protocol: Protocol = Protocol()
    """Start grid, failure thresholds, threads."""
    randomized_seeds: tuple[int, ...] = ()
    """Also evaluate on randomized physics, once per seed (empty: nominal only)."""
    bootstrap_seed: int = 0
    """Seeds the bootstrap of the drift CI."""
    bootstrap_resamples: int = 1000
    """Resamples of the drift CI's bootstrap."""
    recorded_observations: int = 2000
    """Observations of the policy's rollouts kept to compare the two runtimes on."""
    runtime: Literal["torchscript", "onnx"] = "torchscript"
    """Which exported file runs the loop: `policy.pt` on torch or `policy.onnx` on onnxruntime; the
    other one is checked against it on the observations the loop recorded."""

    def __post_init__(self) -> None:
        require_positive(self, "recorded_observations", "bootstrap_resamples")
