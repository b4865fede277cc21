"""A validation's figures as a typed report, read from its `report.json`; light (no torch, no
MuJoCo), so sweeps, benches and the CLI read results without loading the simulation."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPORT_JSON = "report.json"


@dataclass(frozen=True)
class ValidationReport:
    """What validation found: the headline figures, and the whole report as written to `report.json`."""

    start_zero_survival_s: float
    """Survival of the policy's rollout from frame 0 (s)."""
    zero_action_start_zero_survival_s: float
    """The same for the reference fed straight to PD."""
    completion_pct: float
    """Fixed-grid rollouts that reached the end of the clip (%)."""
    mean_survival_s: float
    """Mean survival over the fixed-grid starts (s)."""
    mean_survival_ceiling_s: float
    """The most `mean_survival_s` can be: each start lasting what is left of the clip (s)."""
    zero_action_mean_survival_s: float
    """The same for zero action."""
    E_g_mpbpe: float | None
    """Mean per-body position error in the world frame (mm) over every step survived."""
    E_mpjpe: float | None
    """Mean per-joint position error (mrad)."""
    tracked_pct: float
    """Share of the clip the nominal start-zero rollout tracked within the tolerances (%)."""
    checkpoint_rule: str
    """What chose the exported checkpoint."""
    protocols: dict[str, Any]
    """Per protocol (nominal, randomized, other physics) and controller: start-zero, completion,
    mean survival and tracked share, each a mean with its 95% CI."""
    runtime: str
    """Which exported file ran the loop."""
    onnx_vs_torchscript_max_abs_diff: float
    """Largest difference between the two exported files on the recorded observations."""
    details: dict[str, Any] = field(repr=False, compare=False)
    """Everything in `report.json`: protocols per controller, drift, per-start survival, randomized."""

    def headline(self) -> dict[str, Any]:
        """The figures without the details (a manifest's metrics)."""
        return {name: getattr(self, name) for name in self.__dataclass_fields__ if name != "details"}

    @classmethod
    def from_details(cls, details: dict[str, Any]) -> ValidationReport:
        policy = details["nominal"]["policy"]
        zero = details["nominal"]["zero_action"]
        return cls(
            start_zero_survival_s=policy["start_zero"]["mean_survival_s"],
            zero_action_start_zero_survival_s=zero["start_zero"]["mean_survival_s"],
            completion_pct=policy["fixed_grid"]["completion_pct"],
            mean_survival_s=policy["fixed_grid"]["mean_survival_s"],
            mean_survival_ceiling_s=policy["fixed_grid"]["mean_survival_ceiling_s"],
            zero_action_mean_survival_s=zero["fixed_grid"]["mean_survival_s"],
            E_g_mpbpe=policy["fixed_grid"]["E_g_mpbpe"],
            E_mpjpe=policy["fixed_grid"]["E_mpjpe"],
            tracked_pct=details["tracking"]["start_zero_tracked_pct"]["policy"],
            checkpoint_rule=details["checkpoint"].get("rule", "not recorded by this export"),
            protocols=_headline_protocols(details["protocols"]),
            runtime=details["runtime"]["ran"],
            onnx_vs_torchscript_max_abs_diff=details["runtime"]["onnx_vs_torchscript_max_abs_diff"],
            details=details,
        )

    @classmethod
    def load(cls, folder: Path) -> ValidationReport:
        """The report of a validate artifact."""
        return cls.from_details(json.loads((folder / REPORT_JSON).read_text()))


HEADLINE_FIGURES = ("start_zero_s", "completion_pct", "mean_survival_s", "tracked_pct")
"""What the manifest keeps of each protocol, per controller."""


def _headline_protocols(protocols: dict[str, Any]) -> dict[str, Any]:
    return {
        protocol: {
            controller: {figure: figures[controller][figure] for figure in HEADLINE_FIGURES}
            for controller in ("policy", "zero_action")
        }
        for protocol, figures in protocols.items()
    }
