"""The layout a recording opens with: the 3D scene large on top, its plots side by side below,
the time panel on the shared `time` axis, paused at the start; the camera follows the dancer."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from rd_pipeline.viz.rerun_view import TIME_TIMELINE

SCENE_SHARE = 3.0
PLOTS_SHARE = 1.0
"""The scene gets three quarters of the height, the row of plots one quarter."""

EYE_OFFSET_M = (3.5, 0.0, 0.8)
"""Where the camera starts from what it follows: to its +x side, so a robot drawn beside it
(shifted along +y) stands to its right rather than hidden behind it."""


@dataclass(frozen=True)
class Follow:
    """What the camera follows through the clip: an entity with a moving transform."""

    entity: str
    start: np.ndarray
    """(3,) its position at the start."""


@dataclass(frozen=True)
class Plot:
    """One plot: its title and the series (entity paths) drawn in it, all in one unit."""

    title: str
    series: tuple[str, ...]


def send_layout(rec: rr.RecordingStream, plots: Sequence[Plot], follow: Follow | None) -> None:
    """Store the layout in the recording as its default, so every viewer opens it the same way."""
    rec.send_blueprint(layout(plots, follow), make_active=True, make_default=True)


def layout(plots: Sequence[Plot], follow: Follow | None) -> rrb.Blueprint:
    return rrb.Blueprint(
        _views(plots, follow),
        rrb.TimePanel(state="expanded", timeline=TIME_TIMELINE, play_state="paused"),
        # The entity tree and the selection stay a click away; the scene gets the width.
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )


def _views(plots: Sequence[Plot], follow: Follow | None) -> rrb.Container | rrb.View:
    plotted = [f"- {path}" for plot in plots for path in plot.series]
    scene = rrb.Spatial3DView(name="scene", origin="/", contents=["+ /**", *plotted], eye_controls=_eye(follow))
    if not plots:
        return scene
    row = rrb.Horizontal(*(rrb.TimeSeriesView(name=p.title, origin="/", contents=list(p.series)) for p in plots))
    return rrb.Vertical(scene, row, row_shares=[SCENE_SHARE, PLOTS_SHARE])


def _eye(follow: Follow | None) -> rrb.EyeControls3D | None:
    if follow is None:
        return None  # the viewer's own: the whole scene in view
    return rrb.EyeControls3D(
        position=follow.start + EYE_OFFSET_M,
        look_target=follow.start,
        tracking_entity=follow.entity,
    )
