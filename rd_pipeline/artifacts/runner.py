"""Running a planned DAG: reuse what the store holds whole, compute the rest under each key's
lock, and say what happened through events (the API prints them)."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from rich.console import Console

from rd_pipeline.artifacts.keys import artifact_key, canonical_json
from rd_pipeline.artifacts.manifest import artifact_manifest, write_manifest
from rd_pipeline.artifacts.plan import Pipeline, PlannedStage
from rd_pipeline.artifacts.stage import Stage, StageContext
from rd_pipeline.artifacts.store import ArtifactRef, ArtifactStore
from rd_pipeline.errors import Interrupted, PipelineError
from rd_pipeline.files import failed_write, folder_bytes, write_failure


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
class StageEvent:
    """One thing a run did with a stage, as it happened."""

    kind: Literal["damaged", "wait", "run", "cached", "done"]
    """`damaged`: an artifact failed its check and is recomputed; `wait`: another run holds the
    key; `run`: the stage starts; `cached`/`done`: its artifact was reused / made."""
    stage: str
    """Stage name."""
    key: str
    """Artifact key."""
    path: Path | None = None
    """The artifact's folder, where there is one."""
    seconds: float = 0.0
    """Wall time spent on the stage so far (`cached`, `done`)."""
    detail: str = ""
    """What is wrong (`damaged`)."""


Report = Callable[[StageEvent], None]
"""Where a run's events go."""


def execute(
    pipeline: Pipeline,
    store: ArtifactStore,
    selection: tuple[str | None, str | None, str | None] = (None, None, None),
    force: bool = False,
    resume: bool = False,
    report: Report = lambda event: None,
    console: Console | None = None,
) -> list[StageOutcome]:
    """Run the stages `selection` (`--from`, `--until`, `--only`) picks; cached artifacts are
    reused without doing any work, damaged ones are recomputed, and a key another process is
    computing is waited for, then reused. `console` is the stages' own, for their progress."""
    console = console or Console(stderr=True, emoji=False)
    selected, before = pipeline.select(*selection)
    planned = pipeline.plan(before + selected)
    usable = _usable_artifacts(pipeline, store, planned, selected, force, report)
    refs: dict[str, ArtifactRef] = {}
    outcomes: list[StageOutcome] = []
    for entry in planned:
        began = time.perf_counter()
        ref = usable.get(entry.name)
        if entry.stage in before:
            refs[entry.stage.provides] = _upstream(pipeline, entry, ref)
            continue
        cached = ref is not None
        if ref is None:
            ref, cached = _compute(pipeline, store, entry, refs, console, force, resume, report)
        refs[entry.stage.provides] = ref
        seconds = time.perf_counter() - began
        report(StageEvent("cached" if cached else "done", entry.name, entry.key, ref.path, seconds))
        outcomes.append(StageOutcome(entry.name, entry.key, ref.path, cached, seconds))
    return outcomes


def _upstream(pipeline: Pipeline, entry: PlannedStage, ref: ArtifactRef | None) -> ArtifactRef:
    """An upstream stage's artifact, which a run that starts after it needs whole."""
    if ref is None:
        label = pipeline.label(entry.stage)
        raise PipelineError(
            f"upstream stage '{entry.name}' has no usable artifact {entry.key} for {label}; "
            f"make it first: `rd-pipeline stage {entry.name}` with the same options, or a run through it"
        )
    return ref


def _compute(
    pipeline: Pipeline,
    store: ArtifactStore,
    entry: PlannedStage,
    refs: dict[str, ArtifactRef],
    console: Console,
    force: bool,
    resume: bool,
    report: Report,
) -> tuple[ArtifactRef, bool]:
    """The entry's artifact, made here under its key's lock, or by a concurrent run while this one
    waited for the lock; True where the concurrent run made it."""
    robot = pipeline.stage_robot(entry.stage)
    waited = lambda: report(StageEvent("wait", entry.name, entry.key))
    with store.claim(entry.name, robot, pipeline.motion, entry.key, force, waited) as claim:
        if claim.made is not None:
            return claim.made, True
        assert claim.out is not None  # nothing made: a folder to write
        report(StageEvent("run", entry.name, entry.key))
        context = StageContext(
            robot=robot,
            motion=pipeline.motion,
            params=entry.params,
            inputs=entry.inputs,
            upstream={role: refs[role] for role in entry.stage.requires},
            out_dir=claim.out,
            console=console,
            work_dir=claim.work,
            resume=resume,
            restart=force,
            shorter=_shorter_runs(store, entry, robot, pipeline.motion) if resume else (),
        )
        _run_stage(entry, context)
    return ArtifactRef(entry.name, entry.key, store.folder(entry.name, robot, pipeline.motion) / entry.key), False


def _run_stage(entry: PlannedStage, context: StageContext) -> None:
    """Run the stage into its folder and write the manifest last; an interrupt or a refused
    write is one line."""
    out = context.out_dir
    began = time.perf_counter()
    try:
        metrics = entry.stage.run(context)
        seconds = time.perf_counter() - began
        write_manifest(out, artifact_manifest(entry, context.robot, context.motion, seconds, metrics, out))
    except KeyboardInterrupt:
        raise _interrupted(context, entry.name) from None
    except Exception as exc:
        refused = _refused_write(exc, context)
        if refused is None:
            raise
        raise refused from None


def _usable_artifacts(
    pipeline: Pipeline,
    store: ArtifactStore,
    planned: list[PlannedStage],
    selected: list[Stage],
    force: bool,
    report: Report,
) -> dict[str, ArtifactRef]:
    """Stage name -> its artifact when it exists and is whole.

    The sha256 of every file is checked for the artifacts this run reports as cached (the selected
    stages) and for those a stage of this run will load (upstream of a stage that runs); sizes only
    for the rest. A damaged one is reported and left out, so it is recomputed.
    """
    found: dict[str, ArtifactRef] = {}
    for entry in planned:
        robot = pipeline.stage_robot(entry.stage)
        ref = store.find(entry.stage.name, robot, pipeline.motion, entry.key)
        reported = entry.stage in selected
        if ref is not None and not (force and reported) and _whole(entry, ref, reported, report):
            found[entry.stage.name] = ref
    for entry in reversed(planned):  # a stage recomputed after all loads its own upstream in turn
        name = entry.stage.name
        loaded = any(name in later.upstream and later.stage.name not in found for later in planned)
        hashed = entry.stage in selected  # the first pass hashed it already
        if name in found and loaded and not hashed and not _whole(entry, found[name], True, report):
            del found[name]
    return found


def _whole(entry: PlannedStage, ref: ArtifactRef, full: bool, report: Report) -> bool:
    problem = ref.damage(full)
    if problem is not None:
        report(StageEvent("damaged", entry.name, entry.key, ref.path, detail=problem))
    return problem is None


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
