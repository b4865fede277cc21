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
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from rich.console import Console

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


Selection = tuple[str | None, str | None, str | None]
"""`--from`, `--until`, `--only`: the stages a run selects."""


@dataclass(frozen=True)
class ChosenWindow:
    """The window a plan was clipped to, and how it was chosen."""

    window: Window
    """Its clip, start and end, and joint speed."""
    quantile: float
    """The speed quantile it was chosen at."""
    footing: list[Footing]
    """How the reference's feet stand in each of its seconds."""

    def describe(self) -> str:
        """One line: the clip, the speed it was chosen at, and where its feet stand."""
        speed = f"joint speed p95 {self.window.joint_speed_p95:g} rad/s"
        tilts = [second.lowest_foot_tilt_deg for second in self.footing]
        planted = sum(second.planted_share for second in self.footing) / len(self.footing)
        tilt = f"lowest-foot tilt {min(tilts):.0f}-{max(tilts):.0f} deg by the second"
        feet = f"{tilt}, a foot planted in {planted:.0%} of frames"
        return f"window: {self.window.clip} s at speed quantile {self.quantile:g} ({speed}; {feet})"


def windowed_plan(
    plan_with: Callable[[tuple[str, ...]], workspace.Plan],
    seconds: int,
    quantile: float,
    selection: Selection | None,
    console: Console | None = None,
) -> tuple[workspace.Plan, ChosenWindow]:
    """The plan clipped to the take's `seconds`-long window at speed `quantile`.

    `plan_with(extra)` plans the take with `extra` overrides after the user's. The reference is
    made first when the stages `selection` picks include the one that makes it (None: make
    nothing); otherwise it must be in the store."""
    whole = plan_with(())
    trainer = workspace.providing(whole, "policy")
    chosen = whole.pipeline.params[trainer].clip  # from --clip, --set or the params file
    if chosen:
        raise PipelineError(f"--window {seconds} and {trainer}.clip={chosen} both choose the clip: give one")
    check_window(whole, seconds, quantile)
    if selection is not None:
        _make_reference(whole, selection, console)
    window = speed_window(whole, seconds, quantile)
    choice = ChosenWindow(window, quantile, window_footing(whole, window))
    return plan_with((f"train.clip={window.clip}",)), choice


def _make_reference(plan: workspace.Plan, selection: Selection, console: Console | None) -> None:
    """Run the selected stages up to the one that makes the reference, if it is among them."""
    start, until, only = selection
    selected, _ = plan.pipeline.select(start, until, only)
    maker = workspace.providing(plan, "reference")
    if maker not in {stage.name for stage in selected}:
        return
    if only is not None:
        workspace.run(plan, only=only, console=console)
    else:
        workspace.run(plan, start=start, until=maker, console=console)
