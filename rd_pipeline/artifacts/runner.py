"""The DAG runner: plan the stages for one (robot, motion), compute keys, run what is not cached."""

from __future__ import annotations

import dataclasses
import subprocess
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import cached_property, lru_cache, partial
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape

from rd_pipeline import __version__, paths
from rd_pipeline.artifacts.keys import artifact_key, canonical_json
from rd_pipeline.artifacts.stage import Stage, StageContext, build_params
from rd_pipeline.artifacts.store import ArtifactRef, ArtifactStore, file_records, write_manifest
from rd_pipeline.errors import Interrupted, PipelineError
from rd_pipeline.files import failed_write, file_sha256, folder_bytes, write_failure
from rd_pipeline.lazy import load_deferred


@dataclass(frozen=True)
class PlannedStage:
    """A stage with everything that determines its artifact key."""

    stage: Stage
    """The stage."""
    params: Any
    """Its resolved params."""
    inputs: dict[str, Path]
    """External input files by label."""
    input_hashes: dict[str, str]
    """sha256 of each input file."""
    upstream: dict[str, str]
    """Upstream stage name -> key."""
    key: str
    """The artifact key."""

    @property
    def name(self) -> str:
        return self.stage.name


@dataclass(frozen=True)
class StageOutcome:
    """What happened to one stage in a run."""

    name: str
    """Stage name."""
    key: str
    """Artifact key."""
    path: Path
    """Artifact folder."""
    cached: bool
    """True when the artifact already existed and no work was done."""
    seconds: float
    """Wall time spent, including the cache check."""


@dataclass(frozen=True)
class Pipeline:
    """The stages of one run: a registry, a robot, a motion, a source, params."""

    registry: tuple[Stage, ...]
    """All stages that exist."""
    robot: str | None
    """Robot name; stages that are per robot need one."""
    motion: str
    """Motion name."""
    source: str
    """`bvh` or `csv`."""
    param_values: dict[str, dict[str, Any]]
    """Stage name -> param overrides (profile, params file and `--set`, already layered)."""

    @cached_property
    def params(self) -> dict[str, Any]:
        """Stage name -> its typed params, built once from `param_values` (every value checked)."""
        return {stage.name: build_params(stage, self.param_values.get(stage.name, {})) for stage in self.registry}

    def chain(self) -> list[Stage]:
        """Stages of this source in dependency order (registry order breaks ties)."""
        candidates = [s for s in self.registry if s.source in (None, self.source)]
        ordered: list[Stage] = []
        provided: set[str] = set()
        progress = True
        while progress:
            progress = False
            for stage in candidates:
                if stage not in ordered and all(role in provided for role in stage.requires):
                    ordered.append(stage)
                    provided.add(stage.provides)
                    progress = True
        return ordered

    def select(self, start: str | None, until: str | None, only: str | None) -> tuple[list[Stage], list[Stage]]:
        """(stages to run, upstream stages that must already be cached)."""
        chain = self.chain()
        names = [s.name for s in chain]
        for option, value in (("--from", start), ("--until", until), ("--only", only)):
            if value is None:
                continue
            if value not in {s.name for s in self.registry}:
                known = ", ".join(s.name for s in self.registry)
                raise PipelineError(f"{option}: unknown stage '{value}' (stages: {known})")
            if value not in names:
                raise PipelineError(
                    f"{option}: stage '{value}' is not in the {self.source} pipeline for "
                    f"{self.robot}/{self.motion} (stages: {', '.join(names)})"
                )
        if only is not None:
            if start is not None or until is not None:
                given = "--from" if start is not None else "--until"
                raise PipelineError(f"--only runs one stage; it cannot be combined with {given}")
            start = until = only
        first = names.index(start) if start else 0
        last = names.index(until) if until else len(chain) - 1
        if first > last:
            raise PipelineError(f"--from {start} comes after --until {until}")
        return chain[first : last + 1], chain[:first]

    def plan(self, stages: list[Stage]) -> list[PlannedStage]:
        """Keys for `stages` (which must include their upstream, in order)."""
        planned: list[PlannedStage] = []
        by_role: dict[str, PlannedStage] = {}
        for stage in stages:
            if stage.per_robot and not self.robot:
                raise PipelineError(f"stage '{stage.name}' needs --robot")
            params = self.params[stage.name]
            inputs = stage.inputs(self.robot if stage.per_robot else None, self.motion)
            for label, path in inputs.items():
                paths.require_file(path, f"input '{label}' of stage {stage.name}")
            hashes = {label: file_sha256(path) for label, path in sorted(inputs.items())}
            upstream = {by_role[role].stage.name: by_role[role].key for role in stage.requires}
            key = artifact_key(stage.name, stage.version, dataclasses.asdict(params), upstream, hashes)
            entry = PlannedStage(stage, params, inputs, hashes, upstream, key)
            planned.append(entry)
            by_role[stage.provides] = entry
        return planned


def execute(
    pipeline: Pipeline,
    store: ArtifactStore,
    start: str | None = None,
    until: str | None = None,
    only: str | None = None,
    force: bool = False,
    console: Console | None = None,
    resume: bool = False,
) -> list[StageOutcome]:
    """Run the selected stages; cached artifacts are reused without doing any work, damaged ones are
    recomputed, and a key another process is computing is waited for, then reused."""
    console = console or Console(stderr=True, emoji=False)
    selected, before = pipeline.select(start, until, only)
    planned = pipeline.plan(before + selected)
    usable = _usable_artifacts(pipeline, store, planned, selected, force, console)
    refs: dict[str, ArtifactRef] = {}
    outcomes: list[StageOutcome] = []
    for entry in planned:
        stage = entry.stage
        robot = pipeline.robot if stage.per_robot else None
        label = _label(robot, pipeline.motion)
        began = time.perf_counter()
        ref = usable.get(stage.name)
        if entry.stage in before:
            if ref is None:
                raise PipelineError(
                    f"upstream stage '{stage.name}' has no usable artifact {entry.key} for {label}; "
                    f"make it first: `rd-pipeline stage {stage.name}` with the same options, or a run through it"
                )
            refs[stage.provides] = ref
            continue
        cached = ref is not None
        if ref is None:
            ref, cached = _compute(pipeline, store, entry, refs, console, force, resume)
        refs[stage.provides] = ref
        seconds = time.perf_counter() - began
        if cached:
            console.print(f"[green]cached[/] {stage.name:<9} {escape(label)}  {entry.key}  ({seconds:.2f} s, no work)")
        else:
            console.print(
                f"[green]done[/]   {stage.name:<9} {escape(label)}  {entry.key}  ({seconds:.2f} s) -> {escape(str(ref.path))}"
            )
        outcomes.append(StageOutcome(stage.name, entry.key, ref.path, cached, seconds))
    return outcomes


def _compute(
    pipeline: Pipeline,
    store: ArtifactStore,
    entry: PlannedStage,
    refs: dict[str, ArtifactRef],
    console: Console,
    force: bool,
    resume: bool,
) -> tuple[ArtifactRef, bool]:
    """The entry's artifact, made here under its key's lock, or by a concurrent run while this one
    waited for the lock; True where the concurrent run made it."""
    stage = entry.stage
    robot = pipeline.robot if stage.per_robot else None
    label = _label(robot, pipeline.motion)
    waiting = f"[yellow]wait[/]   {stage.name:<9} {escape(label)}  {entry.key}: another run is computing it"
    with store.locked(stage.name, robot, pipeline.motion, entry.key, on_wait=partial(console.print, waiting)):
        made = _made_meanwhile(store, entry, robot, pipeline.motion, force)
        if made is not None:
            return made, True
        console.print(f"[cyan]run[/]    {stage.name:<9} {escape(label)}  {entry.key}")
        return _run_stage(pipeline, store, entry, refs, console, resume=resume, restart=force), False


def _usable_artifacts(
    pipeline: Pipeline,
    store: ArtifactStore,
    planned: list[PlannedStage],
    selected: list[Stage],
    force: bool,
    console: Console,
) -> dict[str, ArtifactRef]:
    """Stage name -> its artifact when it exists and is whole.

    The sha256 of every file is checked for the artifacts this run reports as cached (the selected
    stages) and for those a stage of this run will load (upstream of a stage that runs); sizes only
    for the rest. A damaged one is reported and left out, so it is recomputed.
    """
    found: dict[str, ArtifactRef] = {}
    for entry in planned:
        robot = pipeline.robot if entry.stage.per_robot else None
        ref = store.find(entry.stage.name, robot, pipeline.motion, entry.key)
        reported = entry.stage in selected
        if ref is not None and not (force and reported) and _whole(ref, reported, console):
            found[entry.stage.name] = ref
    for entry in reversed(planned):  # a stage recomputed after all loads its own upstream in turn
        name = entry.stage.name
        loaded = any(name in later.upstream and later.stage.name not in found for later in planned)
        hashed = entry.stage in selected  # the first pass hashed it already
        if name in found and loaded and not hashed and not _whole(found[name], True, console):
            del found[name]
    return found


def _whole(ref: ArtifactRef, full: bool, console: Console) -> bool:
    problem = ref.damage(full)
    if problem is not None:
        console.print(
            f"[yellow]damaged[/] {escape(str(ref.path))}: {escape(problem)}; it will be recomputed", highlight=False
        )
    return problem is None


def _made_meanwhile(
    store: ArtifactStore, entry: PlannedStage, robot: str | None, motion: str, force: bool
) -> ArtifactRef | None:
    """The artifact a concurrent run finished while this one waited for the key's lock (a damaged
    one found before the wait is still damaged, unless that run replaced it)."""
    if force:
        return None
    ref = store.find(entry.stage.name, robot, motion, entry.key)
    return ref if ref is not None and ref.damage(full=True) is None else None


def _run_stage(
    pipeline: Pipeline,
    store: ArtifactStore,
    entry: PlannedStage,
    refs: dict[str, ArtifactRef],
    console: Console,
    resume: bool,
    restart: bool,
) -> ArtifactRef:
    stage = entry.stage
    robot = pipeline.robot if stage.per_robot else None
    store.remove_abandoned(stage.name, robot, pipeline.motion, entry.key)
    began = time.perf_counter()
    replace = store.find(stage.name, robot, pipeline.motion, entry.key) is not None
    with store.writing(stage.name, robot, pipeline.motion, entry.key, replace=replace) as out:
        context = StageContext(
            robot=robot,
            motion=pipeline.motion,
            params=entry.params,
            inputs=entry.inputs,
            upstream={role: refs[role] for role in stage.requires},
            out_dir=out,
            console=console,
            work_dir=store.work_folder(stage.name, robot, pipeline.motion, entry.key),
            resume=resume,
            restart=restart,
            shorter=_shorter_runs(store, entry, robot, pipeline.motion) if resume else (),
        )
        load_deferred()
        try:
            metrics = stage.run(context)
            seconds = time.perf_counter() - began
            write_manifest(out, _manifest(entry, robot, pipeline.motion, seconds, metrics, out))
        except KeyboardInterrupt:
            raise _interrupted(context, stage.name) from None
        except Exception as exc:
            refused = _refused_write(exc, context)
            if refused is None:
                raise
            raise refused from None
    return ArtifactRef(stage.name, entry.key, store.folder(stage.name, robot, pipeline.motion) / entry.key)


def _manifest(
    entry: PlannedStage, robot: str | None, motion: str, seconds: float, metrics: dict[str, Any], out: Path
) -> dict[str, Any]:
    """What an artifact says of itself: what made it, from what, when, its metrics and its files' hashes."""
    return {
        "stage": entry.stage.name,
        "key": entry.key,
        "robot": robot,
        "motion": motion,
        "params": dataclasses.asdict(entry.params),
        "inputs": {str(path): entry.input_hashes[label] for label, path in entry.inputs.items()},
        "upstream": entry.upstream,
        "code_version": code_version(),
        "created_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "duration_s": round(seconds, 3),
        "metrics": metrics,
        "files": file_records(out),
    }


def _refused_write(exc: Exception, context: StageContext) -> PipelineError | None:
    """A write the disk refused (full, read-only) as one line naming the folder and the space the
    stage had used; None for any other failure."""
    cause = failed_write(exc)
    if cause is None:
        return None
    folders = [context.out_dir, *([context.work_dir] if context.work_dir else [])]
    return write_failure(cause, context.out_dir.parent, folder_bytes(*folders))


def _interrupted(context: StageContext, stage: str) -> KeyboardInterrupt:
    """Ctrl-C in a stage: say where its kept progress is, if it kept any."""
    work = context.work_dir
    if work is None or not work.is_dir() or not any(work.iterdir()):
        return KeyboardInterrupt()
    return Interrupted(f"{stage} kept its progress in {work}; the same command continues from it (--force starts over)")


def _shorter_runs(store: ArtifactStore, entry: PlannedStage, robot: str | None, motion: str) -> tuple[ArtifactRef, ...]:
    """Finished artifacts that `entry` would have made with other values of the stage's `extends`
    params: their key, recomputed from their own params with this entry's version, inputs and
    upstream, is their folder name."""
    stage = entry.stage
    if not stage.extends:
        return ()
    fixed = lambda params: canonical_json({k: v for k, v in params.items() if k not in stage.extends})
    wanted = fixed(dataclasses.asdict(entry.params))
    found = []
    for key in store.keys(stage.name, robot, motion):
        ref = store.find(stage.name, robot, motion, key)
        if ref is None or key == entry.key or ref.damage() is not None:
            continue
        params = ref.manifest.get("params", {})
        if fixed(params) != wanted:
            continue
        recomputed = artifact_key(stage.name, stage.version, params, entry.upstream, entry.input_hashes)
        # Its files are about to seed this run: check their hashes, not only their sizes.
        if recomputed == key and ref.damage(full=True) is None:
            found.append(ref)
    return tuple(found)


def _label(robot: str | None, motion: str) -> str:
    return f"{robot}/{motion}" if robot else motion


@lru_cache(maxsize=1)
def code_version() -> str:
    """`0.1.0+g<commit>` in a git checkout, else the package version."""
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=paths.PROJECT_ROOT,
            capture_output=True,
            text=True,
            timeout=5,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    return f"{__version__}+g{commit}" if commit else __version__


def stage_status(pipeline: Pipeline, store: ArtifactStore, verify: bool = False) -> list[dict[str, Any]]:
    """Per stage of the chain: key, path and state (cached / damaged / resumable / stale / missing),
    or the reason there is no key. File sizes are always checked, their sha256 with `verify`."""
    rows = []
    chain = pipeline.chain()
    for i, stage in enumerate(chain):
        robot = pipeline.robot if stage.per_robot else None
        row: dict[str, Any] = {"stage": stage.name, "robot": robot, "motion": pipeline.motion}
        try:
            entry = pipeline.plan(chain[: i + 1])[-1]
        except PipelineError as exc:
            rows.append({**row, "key": None, "path": None, "state": "missing", "reason": str(exc)})
            continue
        found = store.find(stage.name, robot, pipeline.motion, entry.key)
        damage = found.damage(verify) if found else None
        others = [k for k in store.keys(stage.name, robot, pipeline.motion) if k != entry.key]
        work = store.work_folder(stage.name, robot, pipeline.motion, entry.key)
        running = not found and store.running(stage.name, robot, pipeline.motion, entry.key)
        kept = not found and not running and work.is_dir() and any(work.iterdir())
        continues, progress = stage.kept_progress(work) if kept else (False, "")
        damage = damage or (progress if kept and not continues else None)
        states = (("damaged", damage), ("cached", found), ("running", running), ("resumable", kept), ("stale", others))
        state = next((name for name, holds in states if holds), "missing")
        path = store.folder(stage.name, robot, pipeline.motion) / entry.key
        rows.append({**row, "key": entry.key, "path": str(path), "state": state, "other_keys": others})
        if damage:
            rows[-1]["reason"] = damage
        elif kept:
            rows[-1]["reason"] = progress
        elif running:
            rows[-1]["reason"] = "another run is computing it now"
    return rows
