"""The layout a recording opens with: the 3D scene large on top, its plots side by side below,
the time panel on the shared `time` axis, paused at the start."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import rerun as rr
import rerun.blueprint as rrb

from rd_pipeline.viz.rerun_view import TIME_TIMELINE

SCENE_SHARE = 3.0
PLOTS_SHARE = 1.0
"""The scene gets three quarters of the height, the row of plots one quarter."""


@dataclass(frozen=True)
class Plot:
    """One plot: its title and the series (entity paths) drawn in it, all in one unit."""

    title: str
    series: tuple[str, ...]


def send_layout(rec: rr.RecordingStream, plots: Sequence[Plot]) -> None:
    """Store the layout in the recording as its default, so every viewer opens it the same way."""
    rec.send_blueprint(layout(plots), make_active=True, make_default=True)


def layout(plots: Sequence[Plot]) -> rrb.Blueprint:
    return rrb.Blueprint(
        _views(plots),
        rrb.TimePanel(state="expanded", timeline=TIME_TIMELINE, play_state="paused"),
        # The entity tree and the selection stay a click away; the scene gets the width.
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )


def _views(plots: Sequence[Plot]) -> rrb.Container | rrb.View:
    plotted = [f"- {path}" for plot in plots for path in plot.series]
    scene = rrb.Spatial3DView(name="scene", origin="/", contents=["+ /**", *plotted])
    if not plots:
        return scene
    row = rrb.Horizontal(*(rrb.TimeSeriesView(name=p.title, origin="/", contents=list(p.series)) for p in plots))
    return rrb.Vertical(scene, row, row_shares=[SCENE_SHARE, PLOTS_SHARE])
