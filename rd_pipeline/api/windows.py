"""Choose the stretch of a take to train on by how fast its reference moves.

    plan = workspace.plan("h1_2", "dance2_subject4", profile="cpu")
    workspace.run(plan, until=workspace.providing(plan, "reference"))
    window = windows.speed_window(plan, seconds=10, quantile=0.5)
    clipped = workspace.plan("h1_2", "dance2_subject4", profile="cpu", overrides=(f"train.clip={window.clip}",))

A take's ten seconds can be standing prelude or its most violent moment; the reference's joint
speed tells them apart (`rd_pipeline.motion.activity`). The window is read from the whole take's
reference, which no training param changes, so any plan of the take can choose it.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from rd_pipeline.api import workspace
from rd_pipeline.errors import PipelineError

if TYPE_CHECKING:
    from rd_pipeline.motion.activity import Window
    from rd_pipeline.motion.footing import Footing


def check_window(plan: workspace.Plan, seconds: int, quantile: float) -> None:
    """Refuse, before any stage runs, a window that no reference of this take can give: shorter
    than a second, a quantile outside [0, 1], or longer than the take's whole seconds."""
    take = f"{plan.robot}/{plan.motion}"
    if seconds < 1:
        raise PipelineError(f"window of {take}: must last 1 s or more, got {seconds} s")
    if not 0.0 <= quantile <= 1.0:
        raise PipelineError(f"window of {take}: speed quantile {quantile:g} is outside [0, 1]")
    duration_s = workspace.source_duration_s(plan.pipeline)
    if seconds > math.floor(duration_s):
        raise PipelineError(f"window of {take}: a {seconds} s window does not fit the {duration_s:.1f} s take")


def speed_window(plan: workspace.Plan, seconds: int, quantile: float) -> Window:
    """The take's `seconds`-long window whose joint-speed p95 is nearest `quantile` of all its
    windows' (1: the busiest; 0.5: a typical stretch), read from the reference in the store."""
    check_window(plan, seconds, quantile)
    maker = workspace.providing(plan, "reference")
    if workspace.artifact(plan, maker) is None:
        take = f"{plan.robot}/{plan.motion}"
        raise PipelineError(f"window of {take}: chosen from the reference, which stage '{maker}' has not made yet")
    from rd_pipeline.motion.activity import window_at_speed_quantile  # loads MuJoCo: only when a window is asked

    try:
        return window_at_speed_quantile(workspace.reference(plan), seconds, quantile)
    except ValueError as exc:
        raise PipelineError(f"window of {plan.robot}/{plan.motion}: {exc}") from None


def window_footing(plan: workspace.Plan, window: Window) -> list[Footing]:
    """How the reference's feet stand in each second of `window` (a flat-soled robot asked to
    stand on a tilted sole stands on its edge)."""
    from rd_pipeline.motion.footing import footing_per_second
    from rd_pipeline.robots.config import load_robot_config

    assert plan.robot is not None  # a window is chosen from a robot's reference
    feet = load_robot_config(plan.robot).foot_bodies
    return footing_per_second(workspace.reference(plan), feet)[window.start_s : window.end_s]
