"""What the dance-window benches take from a validation, named as their result files name it."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rd_pipeline.api import workspace
from rd_pipeline.evaluation.validation_report import ValidationReport

if TYPE_CHECKING:
    from rd_pipeline.motion.reference import ReferenceMotion


def fixed_grid_fields(validation: ValidationReport) -> dict[str, Any]:
    """The fixed grid's starts; the policy's survival and endings from each beside zero action's."""
    nominal = validation.details["nominal"]
    policy = nominal["policy"]["per_start"]
    zero_action = nominal["zero_action"]["per_start"]
    return {
        "fixed_grid_start_s": policy["start_s"],
        "fixed_grid_survival_s": policy["survival_s"],
        "fixed_grid_most_s": policy["most_s"],
        "fixed_grid_zero_action_survival_s": zero_action["survival_s"],
        "fixed_grid_ended_by": policy["ended_by"],
        "fixed_grid_zero_action_ended_by": zero_action["ended_by"],
    }


def validated_reference(plan: workspace.Plan, validation: ValidationReport) -> ReferenceMotion:
    """The frames the validation tracked, from whichever stage made the reference (retarget or import)."""
    clip = validation.details["reference"]
    reference = workspace.reference(plan, clip["stage"])
    return reference.frames(clip["start_frame"], clip["end_frame"])
