"""A run's stage events as the console lines a person reads while it works."""

from __future__ import annotations

from rich.console import Console
from rich.markup import escape

from rd_pipeline.artifacts.plan import Pipeline
from rd_pipeline.artifacts.runner import Report, StageEvent


def stage_lines(pipeline: Pipeline, console: Console) -> Report:
    """Print each event of a run of `pipeline` as one line on `console`."""
    labels = {stage.name: pipeline.label(stage) for stage in pipeline.registry}

    def say(event: StageEvent) -> None:
        console.print(_line(event, escape(labels[event.stage])), highlight=False)

    return say


def _line(event: StageEvent, label: str) -> str:
    name = f"{event.stage:<9}"
    path = escape(str(event.path))
    if event.kind == "damaged":
        return f"[yellow]damaged[/] {path}: {escape(event.detail)}; it will be recomputed"
    if event.kind == "wait":
        return f"[yellow]wait[/]   {name} {label}  {event.key}: another run is computing it"
    if event.kind == "run":
        return f"[cyan]run[/]    {name} {label}  {event.key}"
    if event.kind == "cached":
        return f"[green]cached[/] {name} {label}  {event.key}  ({event.seconds:.2f} s, no work)"
    return f"[green]done[/]   {name} {label}  {event.key}  ({event.seconds:.2f} s) -> {path}"
