"""What a DAG stage is: a name, a version, typed params, the roles it needs and provides, a run function.

Stages are connected by roles, not by names: `parse` provides `human_motion`, `retarget` needs it and
provides `reference`, `import` provides `reference` from a CSV instead. The runner picks the stages
of one source and orders them by these roles, so adding a stage never touches the runner.
"""

from __future__ import annotations

import dataclasses
import time
import typing
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from rd_pipeline.artifacts.store import ArtifactRef
from rd_pipeline.errors import PipelineError, nearest
from rd_pipeline.params import ParamRangeError, require_default_sign

T = TypeVar("T")


@dataclass(frozen=True)
class StageContext:
    """What a stage's run function gets."""

    robot: str | None
    """Robot name (None for robot-independent stages)."""
    motion: str
    """Motion name."""
    params: Any
    """The stage's frozen params dataclass."""
    inputs: dict[str, Path]
    """External input files by label."""
    upstream: dict[str, ArtifactRef]
    """Upstream artifacts by the role they provide."""
    out_dir: Path
    """Temporary folder to write into; it becomes the artifact when the stage returns."""
    console: Console = field(default_factory=Console)
    """Where progress and messages go."""
    work_dir: Path | None = None
    """A folder that survives an interrupted run of this key (long stages keep checkpoints there)."""
    resume: bool = False
    """`--resume`: the stage may also grow a finished shorter run (`shorter`)."""
    restart: bool = False
    """`--force`: discard what `work_dir` holds and start over (by default a stage continues from it)."""
    shorter: tuple[ArtifactRef, ...] = ()
    """With `resume`: finished artifacts of this stage, version, inputs and upstream whose params
    differ from `params` only in the stage's `extends` fields; the stage decides which it can grow."""

    @property
    def robot_name(self) -> str:
        """The robot of a per-robot stage (the runner plans none without one)."""
        if self.robot is None:
            raise PipelineError(f"{self.motion}: this stage needs --robot")
        return self.robot

    def track(self, items: Iterable[T], total: int, description: str) -> Iterator[T]:
        """Iterate with a progress bar (ETA included) for long loops."""
        with self.progress(total, description) as advance:
            for item in items:
                yield item
                advance()

    @contextmanager
    def progress(self, total: int, description: str, done: int = 0) -> Iterator[Callable[..., None]]:
        """A progress bar with ETA over `total` items of which `done` are finished (a continued
        run); the yielded `advance(status="...")` moves it and shows a status line.

        Off a terminal (a log, a pipe) it prints a plain line at every tenth of the work instead.
        """
        if not self.console.is_terminal:
            yield _plain_progress(self.console, total, description, done)
            return
        columns = (
            TextColumn("  {task.description}"),
            BarColumn(),
            TextColumn("{task.completed}/{task.total}"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            TextColumn("{task.fields[status]}"),
        )
        with Progress(*columns, console=self.console, transient=True) as bar:
            task = bar.add_task(description, total=total, completed=done, status="")

            def advance(status: str = "") -> None:
                bar.update(task, advance=1, status=status)

            yield advance


def _plain_progress(console: Console, total: int, description: str, done: int) -> Callable[..., None]:
    began = time.perf_counter()
    step = max(1, total // 10)

    def advance(status: str = "") -> None:
        nonlocal done
        done += 1
        if done % step == 0 or done == total:
            minutes = (time.perf_counter() - began) / 60
            console.print(escape(f"  {description}: {done}/{total} ({minutes:.1f} min)  {status}"), highlight=False)

    return advance


@dataclass(frozen=True)
class Stage:
    """One DAG stage."""

    name: str
    """Name on the command line and in artifact paths."""
    version: int
    """Bump when the code changes what the stage writes; part of the artifact key."""
    description: str
    """One line for `--help` and `status`."""
    params: type
    """Frozen dataclass of the stage's parameters (defaults = the embedded profile)."""
    provides: str
    """Role of the artifact it writes."""
    run: Callable[[StageContext], dict[str, Any]]
    """Writes files into `ctx.out_dir` and returns the manifest's metrics."""
    inputs: Callable[[str | None, str], dict[str, Path]] = lambda robot, motion: {}
    """(robot, motion) -> external input files by label (hashed into the key)."""
    requires: tuple[str, ...] = ()
    """Roles of the upstream artifacts it reads."""
    source: str | None = None
    """For head stages: the raw-data source they read (`bvh` or `csv`)."""
    per_robot: bool = True
    """Whether artifacts are per robot (`<stage>/<robot>/<motion>`) or shared (`<stage>/<motion>`)."""
    headline: tuple[str, ...] = ()
    """Manifest metrics shown in the summary at the end of a run."""
    report: str | None = None
    """A file of the artifact people read first (shown at the end of a run)."""
    kept_progress: Callable[[Path], tuple[bool, str]] = lambda work: (
        True,
        f"an interrupted run kept its progress in {work}; `run` continues from it",
    )
    """For `status`, given the work folder an interrupted run left: whether a rerun continues
    from it, and one line saying what it holds (or what is wrong with it)."""
    extends: tuple[str, ...] = ()
    """Params a run may grow (training iterations): with `--resume` it may continue from a finished
    artifact of this stage that differs from it only in these (`StageContext.shorter`)."""


def typed_config(config_type: type[T], values: dict[str, Any], prefix: str) -> T:
    """A config dataclass from nested values (a manifest's recorded params), each value checked
    against its field's type; `prefix` names the fields in errors (`train`)."""
    return _override(config_type(), values, prefix)


def build_params(stage: Stage, values: dict[str, Any]) -> Any:
    """The stage's params from defaults overridden by `values`, each checked against its type.

    Params may nest frozen dataclasses (e.g. `weights.feet_position`); `values` may give them as
    nested mappings (params files) or dotted names (`--set`).
    """
    return _override(stage.params(), values, stage.name)


def _override(defaults: Any, values: dict[str, Any], prefix: str) -> Any:
    known = {f.name: f for f in dataclasses.fields(defaults)}
    nested: dict[str, dict[str, Any]] = {}
    flat: dict[str, Any] = {}
    for name, value in values.items():
        head, dot, rest = name.partition(".")
        if dot:
            nested.setdefault(head, {})[rest] = value
        elif isinstance(value, dict):
            nested.setdefault(head, {}).update(value)
        else:
            flat[name] = value
    changes = {}
    for name in [*flat, *nested]:
        if name not in known:
            hint = nearest(name, known)
            raise PipelineError(f"unknown parameter '{prefix}.{name}'{hint} (known: {', '.join(known) or 'none'})")
    hints = typing.get_type_hints(type(defaults))
    for name, value in flat.items():
        default = getattr(defaults, name)
        if dataclasses.is_dataclass(default):
            raise PipelineError(f"parameter '{prefix}.{name}' is a group; set its fields ({prefix}.{name}.<field>)")
        changes[name] = _coerce(f"{prefix}.{name}", value, default)
        choices = typing.get_args(hints[name]) if typing.get_origin(hints[name]) is typing.Literal else ()
        if choices and changes[name] not in choices:
            raise PipelineError(
                f"parameter '{prefix}.{name}' must be one of {', '.join(map(str, choices))}, got '{changes[name]}'"
            )
    for name, group in nested.items():
        default = getattr(defaults, name)
        if not dataclasses.is_dataclass(default):
            raise PipelineError(f"parameter '{prefix}.{name}' has no fields")
        changes[name] = _override(default, group, f"{prefix}.{name}")
    try:
        result = dataclasses.replace(defaults, **changes)
    except ParamRangeError as exc:
        raise PipelineError(f"parameter '{prefix}.{exc.field}' {exc.message}") from None
    for name in flat:  # after the dataclass's own, more specific checks
        require_default_sign(f"{prefix}.{name}", changes[name], getattr(defaults, name))
    return result


def _coerce(name: str, value: Any, default: Any) -> Any:
    """Make `value` (possibly a string from `--set`) the type of the default, or say why not."""
    kind = type(default)
    if isinstance(value, str) and kind is tuple:  # `--set x=1,2,3` or `x=[1,2,3]`
        items = [item.strip() for item in value.strip().strip("[]()").split(",") if item.strip()]
        like = default[0] if default else None
        value = tuple(_coerce(name, item, like) if like is not None else _number_or_text(item) for item in items)
    if isinstance(value, str) and kind is not str:
        text = value.strip()
        if kind is bool:
            if text.lower() not in ("true", "false"):
                raise PipelineError(f"parameter '{name}' must be true or false, got '{value}'")
            return text.lower() == "true"
        try:
            value = int(text) if kind is int else float(text) if kind is float else value
        except ValueError:
            raise PipelineError(f"parameter '{name}' must be {_KIND_NAMES[kind]}, got '{value}'") from None
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if kind is tuple and isinstance(value, list):
        value = tuple(value)
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise PipelineError(f"parameter '{name}' must be {_KIND_NAMES.get(kind, 'a ' + kind.__name__)}, got {value!r}")
    return value


_KIND_NAMES = {int: "an integer", float: "a number", str: "a string", bool: "true or false", tuple: "a list"}


def _number_or_text(text: str) -> int | float | str:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text
