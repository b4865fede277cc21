"""The `rd-pipeline` command line: tyro parses a subcommand's arguments, `commands` carries it out."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable
from typing import Any

import tyro
from rich.console import Console
from rich.markup import escape

from rd_pipeline.cli.args import (
    Ablate,
    ExportMotion,
    FetchLafan,
    Motions,
    Plan,
    Robots,
    Run,
    StageCommand,
    Status,
    Sweep,
    View,
)
from rd_pipeline.errors import Interrupted, PipelineError, ShareDone


def main(argv: list[str] | None = None) -> int:
    try:
        command = _parse(argv)
    except BrokenPipeError:  # `rd-pipeline run --help | head`
        return _reader_left()
    # Names, values and paths users give are printed literally: no emoji codes (`:100:`), no markup.
    console = Console(stderr=True, soft_wrap=True, emoji=False)
    stopped_by = _stop_on_sigterm()
    try:
        return _dispatch(command, console)
    except PipelineError as exc:
        console.print(f"[red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True)
        return 2
    except ShareDone as exc:
        console.print(f"done: {escape(str(exc))}", highlight=False, soft_wrap=True)
        return 0
    except KeyboardInterrupt as exc:
        kept = f"; {escape(str(exc))}" if isinstance(exc, Interrupted) else ""
        by = "" if stopped_by[-1] == signal.SIGINT else f" by {stopped_by[-1].name}"
        console.print(f"[red]interrupted[/]{by}: no partial artifact was kept{kept}")
        return 128 + stopped_by[-1]
    except BrokenPipeError:  # `rd-pipeline robots | head`
        return _reader_left()


def _stop_on_sigterm() -> list[signal.Signals]:
    """Make SIGTERM (a supervisor, `kill`) stop a run as Ctrl-C does: the stage cleans up, keeps
    its progress and says so. Returns the list the handler appends the signal that came to."""
    stopped_by = [signal.SIGINT]

    def stop(signum: int, frame: object) -> None:
        stopped_by.append(signal.Signals(signum))
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stop)
    return stopped_by


def _reader_left() -> int:
    """The reader of stdout left: say nothing more, not even while Python flushes at exit."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return 0


def _parse(argv: list[str] | None) -> object:
    return tyro.extras.subcommand_cli_from_dict(
        {
            "run": Run,
            "plan": Plan,
            "stage": StageCommand,
            "status": Status,
            "view": View,
            "export-motion": ExportMotion,
            "fetch-lafan": FetchLafan,
            "robots": Robots,
            "motions": Motions,
            "sweep": Sweep,
            "ablate": Ablate,
        },
        prog="rd-pipeline",
        args=argv,
        description="LAFAN1 mocap -> humanoid dance policies, one DAG per (robot, motion).",
    )


def _dispatch(command: object, console: Console) -> int:
    # Imported once the arguments are parsed: the API registers torch lazily in sys.modules, and tyro
    # then loads all of it to offer torch.device parsing (seconds a cached run should not pay).
    from rd_pipeline.cli import commands

    handlers: dict[type, Callable[[Any, Console], int]] = {
        Run: commands.run,
        Plan: commands.plan,
        StageCommand: commands.stage,
        Status: commands.status,
        View: commands.view,
        ExportMotion: commands.export_motion,
        FetchLafan: commands.fetch_lafan,
        Robots: commands.robots,
        Motions: commands.motions,
        Sweep: commands.sweep,
        Ablate: commands.ablate,
    }
    return handlers[type(command)](command, console)


def entry_point() -> None:
    sys.exit(main())
