"""What each `rd-pipeline` subcommand does (the CLI module only parses arguments)."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from rich.console import Console
from rich.table import Table

from rd_pipeline import paths
from rd_pipeline.artifacts.runner import Pipeline, execute, resolve_source, stage_status
from rd_pipeline.artifacts.stage import build_params
from rd_pipeline.artifacts.store import MANIFEST, ArtifactStore
from rd_pipeline.errors import PipelineError
from rd_pipeline.params import layered_params

if TYPE_CHECKING:
    from rd_pipeline.cli import (
        Ablate,
        ExportMotion,
        FetchLafan,
        Motions,
        Robots,
        Run,
        StageCommand,
        Status,
        Sweep,
        View,
    )


def _registry():
    from rd_pipeline.stages import REGISTRY

    return REGISTRY


def _pipeline(robot, motion, profile, source, params_file, assignments, seed=None) -> Pipeline:
    registry = _registry()
    names = [s.name for s in registry]
    if robot is not None:
        from rd_pipeline.robots.config import load_robot_config

        load_robot_config(robot)  # unknown robot: one clear line before anything else
    values = layered_params(profile, names, params_file, assignments)
    for stage in registry:  # every value is checked now, also for stages this command will not run
        build_params(stage, values.get(stage.name, {}))
    if seed is not None:
        for stage in registry:
            if "seed" in {f.name for f in dataclasses.fields(stage.params)}:
                values.setdefault(stage.name, {}).setdefault("seed", seed)
    return Pipeline(registry, robot, motion, resolve_source(robot, motion, source), values)


def run(cmd: Run, console: Console) -> int:
    assignments = (
        cmd.set
        + ((f"train.clip={cmd.clip}",) if cmd.clip else ())
        + ((f"train.env.backend={cmd.backend}",) if cmd.backend else ())
    )
    pipeline = _pipeline(cmd.robot, cmd.motion, cmd.profile, cmd.source, cmd.params_file, assignments, cmd.seed)
    store = ArtifactStore(paths.artifacts_dir())
    console.print(f"rd-pipeline: {cmd.robot}/{cmd.motion} from {pipeline.source}, artifacts in {store.root}")
    outcomes = execute(
        pipeline,
        store,
        start=cmd.from_,
        until=cmd.until,
        only=cmd.only,
        force=cmd.force,
        console=console,
        resume=cmd.resume,
    )
    print_summary(pipeline, outcomes, console)
    return 0


def print_summary(pipeline: Pipeline, outcomes: list, console: Console) -> None:
    """Per stage: cached or ran, time, headline metrics; then the report to read."""
    stages = {s.name: s for s in pipeline.registry}
    console.print(f"summary {pipeline.robot}/{pipeline.motion}:", highlight=False)
    report = None
    for outcome in outcomes:
        stage = stages[outcome.name]
        metrics = json.loads((outcome.path / MANIFEST).read_text()).get("metrics", {})
        shown = "  ".join(f"{name}={_short(metrics[name])}" for name in stage.headline if name in metrics)
        state = "cached" if outcome.cached else "ran"
        console.print(f"  {outcome.name:<9} {state:<6} {outcome.seconds:7.1f} s  {shown}", highlight=False)
        if stage.report:
            report = outcome.path / stage.report
    if report is not None:
        console.print(f"report: {report}", highlight=False)


def _short(value: object) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def stage(cmd: StageCommand, console: Console) -> int:
    by_name = {s.name: s for s in _registry()}
    if cmd.name not in by_name:
        raise PipelineError(f"unknown stage '{cmd.name}' (stages: {', '.join(by_name)})")
    chosen = by_name[cmd.name]
    pipeline = _pipeline(cmd.robot, cmd.motion, cmd.profile, chosen.source, cmd.params_file, cmd.set, cmd.seed)
    execute(
        pipeline,
        ArtifactStore(paths.artifacts_dir()),
        only=cmd.name,
        force=cmd.force,
        console=console,
        resume=cmd.resume,
    )
    return 0


def status(cmd: Status, console: Console) -> int:
    store = ArtifactStore(paths.artifacts_dir())
    if cmd.robot and cmd.motion:
        pairs = [(cmd.robot, cmd.motion)]
    else:
        pairs = _pairs_in_store(store, cmd.robot, cmd.motion)
    reports = []
    for robot, motion in pairs:
        pipeline = _pipeline(robot, motion, cmd.profile, cmd.source, cmd.params_file, cmd.set)
        if robot is None:  # a motion with only robot-independent artifacts so far
            pipeline = dataclasses.replace(pipeline, registry=tuple(s for s in pipeline.registry if not s.per_robot))
        reports.append(
            {
                "robot": robot,
                "motion": motion,
                "source": pipeline.source,
                "stages": stage_status(pipeline, store, cmd.verify),
            }
        )
    if cmd.json:
        print(json.dumps({"artifacts": str(store.root), "pipelines": reports}, indent=2))
        return 0
    if not reports:
        console.print(f"no artifacts in {store.root}")
    colors = {"cached": "green", "damaged": "red", "stale": "yellow", "missing": "red"}
    for report in reports:
        table = Table(title=f"{report['robot'] or '(any robot)'}/{report['motion']} ({report['source']})")
        for column in ("stage", "state", "key", "path"):
            table.add_column(column)
        for row in report["stages"]:
            state = f"[{colors[row['state']]}]{row['state']}[/]"
            where = row["path"] or ""
            reason = row.get("reason")
            table.add_row(
                row["stage"], state, row["key"] or "-", f"{where} ({reason})" if where and reason else reason or where
            )
        out = Console()
        if not out.is_terminal:  # piped or logged: whole paths, not a table folded at 80 columns
            out.width = 1000
        out.print(table)
    return 0


def _pairs_in_store(store: ArtifactStore, robot: str | None, motion: str | None) -> list[tuple[str | None, str]]:
    """(robot, motion) pairs that have any artifact, filtered; robot None for robot-independent ones only."""
    found: set[tuple[str | None, str]] = set()
    for stage in _registry():
        root = store.root / stage.name
        folders = root.glob("*/*") if stage.per_robot else root.glob("*")
        for folder in folders if root.is_dir() else []:
            pair = (folder.parent.name, folder.name) if stage.per_robot else (None, folder.name)
            found.add(pair)
    with_robot = {m for r, m in found if r is not None}
    pairs = [(r, m) for r, m in found if r is not None or m not in with_robot]
    pairs = [(r, m) for r, m in pairs if (robot is None or r in (robot, None)) and (motion is None or m == motion)]
    return sorted(pairs, key=lambda p: (p[1], p[0] or ""))


def view(cmd: View, console: Console) -> int:
    from rd_pipeline.viz.recording import TRACKED_FILE, record_motion
    from rd_pipeline.viz.rerun_view import display_available

    pipeline = _pipeline(cmd.robot, cmd.motion, cmd.profile, cmd.source, None, ())
    store = ArtifactStore(paths.artifacts_dir())
    # Only stages that produce motion are needed; they are computed or taken from the cache.
    motion_stages = [s.name for s in pipeline.chain() if s.provides in ("human_motion", "reference")]
    outcomes = execute(pipeline, store, until=motion_stages[-1], console=console) if motion_stages else []
    artifacts = {o.name: o.path for o in outcomes}
    # The tracked robot is shown when this configuration has been validated; view never trains.
    planned = {entry.stage.name: entry for entry in pipeline.plan(pipeline.chain())}
    validated = (
        store.find("validate", cmd.robot, cmd.motion, planned["validate"].key) if "validate" in planned else None
    )
    tracked = validated.path / TRACKED_FILE if validated else None
    out = cmd.out
    if out is None and not display_available():
        out = store.root / "views" / f"{cmd.robot}_{cmd.motion}.rrd"
        console.print("no display here (DISPLAY and WAYLAND_DISPLAY are unset): writing the recording instead")
    path = record_motion(cmd.robot, cmd.motion, artifacts, out, tracked)
    if path is not None:
        console.print(f"wrote {path}; open it with `rerun {path}` (pip package rerun-sdk) on a machine with a display")
        if cmd.spawn:
            subprocess.Popen([sys.executable, "-m", "rerun", str(path)])
    return 0


def export_motion(cmd: ExportMotion, console: Console) -> int:
    from rd_pipeline.export.motion_csv import write_dataset_csv
    from rd_pipeline.export.motion_mjlab import write_mjlab_npz
    from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
    from rd_pipeline.robots import load_robot

    if cmd.fps is not None and not cmd.fps > 0:
        raise PipelineError(f"--fps must be positive, got {cmd.fps:g}")
    pipeline = _pipeline(cmd.robot, cmd.motion, cmd.profile, cmd.source, None, ())
    made_by = next(s.name for s in pipeline.chain() if s.provides == "reference")
    outcomes = execute(pipeline, ArtifactStore(paths.artifacts_dir()), until=made_by, console=console)
    folder = next(o.path for o in outcomes if o.name == made_by)
    reference = ReferenceMotion.load(folder / REFERENCE_FILE)
    robot = load_robot(cmd.robot)
    missing: list[str] = []
    if cmd.format == "csv":
        fps = cmd.fps or 30.0
        frames = write_dataset_csv(reference, robot.config, cmd.out, fps)
    else:
        fps = cmd.fps or reference.fps
        frames, missing = write_mjlab_npz(reference, robot, cmd.out, fps)
    console.print(f"wrote {cmd.out}: {frames} frames at {fps:g} fps from {made_by} {folder.name}", highlight=False)
    if missing:
        console.print(f"mjlab's {cmd.robot} model has joints this one lacks, written as 0: {', '.join(missing)}")
    return 0


def fetch_lafan(cmd: FetchLafan, console: Console) -> int:
    from rd_pipeline.motion.lafan_download import install_lafan

    installed = install_lafan(cmd.zip, paths.lafan_dir(), console)
    console.print(f"installed {len(installed)} BVH files into {paths.lafan_dir()}")
    return 0


def robots(cmd: Robots, console: Console) -> int:
    from rd_pipeline.robots.config import available_robots, load_robot_config

    for name in available_robots():
        config = load_robot_config(name)
        print(
            f"{name:<6} {len(config.joint_names):>2} joints, {len(config.policy_joints):>2} policy  {config.description}"
        )
    return 0


def motions(cmd: Motions, console: Console) -> int:
    found = paths.available_motions()
    if not found:
        raise PipelineError(f"no motions: {paths.lafan_dir()} has no BVH and RD_RETARGETED_DIR is not set or empty")
    for name, sources in found.items():
        print(f"{name:<18} {' '.join(sources)}")
    return 0


SWEEP_COLUMNS = (
    "start_zero_survival_s",
    "zero_action_start_zero_survival_s",
    "mean_survival_s",
    "completion_pct",
    "E_g_mpbpe",
    "E_mpjpe",
)
"""Summary-table columns, from each trial's validate manifest."""


def trial_artifact(trial, profile: str | None, stage: str) -> Path | None:
    """The folder of the `stage` artifact a sweep trial's run produced (found by its planned key), or None."""
    pipeline = _pipeline(trial.robot, trial.motion, profile, None, None, trial.assignments, trial.seed)
    planned = {e.stage.name: e for e in pipeline.plan(pipeline.chain())}
    found = ArtifactStore(paths.artifacts_dir()).find(stage, trial.robot, trial.motion, planned[stage].key)
    return found.path if found else None


def training_runs(train: Path) -> list[tuple[str, float]]:
    """(key, seconds) of each run behind a train artifact, oldest first: a grown training continues
    the shorter runs before it."""
    manifest = json.loads((train / MANIFEST).read_text())
    this_run = (manifest["key"], manifest["duration_s"])
    earlier = manifest["metrics"].get("continued_from")
    if not earlier:
        return [this_run]
    if not (train.parent / earlier / MANIFEST).is_file():
        raise PipelineError(f"{train}: continues run {earlier}, which is no longer in the store; its time is unknown")
    return [*training_runs(train.parent / earlier), this_run]


def training_seconds(train: Path) -> float:
    """A train artifact's seconds, with those of the shorter runs a grown training continued."""
    return sum(seconds for _, seconds in training_runs(train))


def validation_report(trial, profile: str | None) -> Path | None:
    """The `report.json` a sweep trial's run produced, or None."""
    folder = trial_artifact(trial, profile, "validate")
    return folder / "report.json" if folder else None


def _run_trials(cmd: Sweep, trials, label: str, console: Console):
    from rd_pipeline.artifacts.keys import artifact_key
    from rd_pipeline.sweeps.runner import TrialResult, run_sweep, write_summary

    if cmd.executor not in ("local", "ray"):
        raise PipelineError(f"executor must be local or ray, got '{cmd.executor}'")
    find_report = lambda trial: validation_report(trial, cmd.profile)

    def on_result(result: TrialResult) -> None:
        status = "[green]ok[/]" if result.ok else f"[red]failed[/] {result.error}"
        console.print(f"trial {result.trial.label}: {status} ({result.seconds:.0f} s)")

    for trial in trials:  # bad parameters fail here, before any work, with one line
        _pipeline(trial.robot, trial.motion, cmd.profile, None, None, trial.assignments, trial.seed)
    # The same trials and profile always land in the same folder.
    described = {"trials": [t.label for t in trials], "sets": [t.assignments for t in trials], "profile": cmd.profile}
    name = f"{label}-{artifact_key('sweep', 1, described, {}, {})[:8]}"
    console.print(
        f"{label}: {len(trials)} trials ({cmd.executor}), results in {paths.artifacts_dir() / 'sweeps' / name}"
    )
    results = run_sweep(
        trials, cmd.profile, cmd.executor, cmd.workers, cmd.ray_address, find_report, on_result, resume=cmd.resume
    )
    out = paths.artifacts_dir() / "sweeps" / name
    summary = write_summary(results, out, SWEEP_COLUMNS)
    table = Table("trial", "status", *SWEEP_COLUMNS, title=f"{label} summary")
    for r in results:
        table.add_row(
            r.trial.label,
            "ok" if r.ok else "failed",
            *("–" if r.metrics.get(c) is None else f"{r.metrics[c]:.2f}" for c in SWEEP_COLUMNS),
        )
    console.print(table)
    console.print(f"wrote {summary}")
    return results, out


def sweep(cmd: Sweep, console: Console) -> int:
    from rd_pipeline.sweeps.runner import make_trials

    trials = make_trials(list(cmd.robots), list(cmd.motions), list(cmd.seeds), {"default": cmd.set})
    results, _ = _run_trials(cmd, trials, "sweep", console)
    return 0 if all(r.ok for r in results) else 1


def ablate(cmd: Ablate, console: Console) -> int:
    from rd_pipeline.sweeps.ablation import STUDIES, ablation_table, write_ablation
    from rd_pipeline.sweeps.runner import make_trials

    arms = STUDIES[cmd.study]
    unknown = [arm for arm in cmd.arms if arm not in arms]
    if unknown:
        raise PipelineError(f"--arms {unknown[0]}: not an arm of the {cmd.study} study (arms: {', '.join(arms)})")
    chosen = cmd.arms or tuple(arms)
    variants = {arm: cmd.set + arms[arm] for arm in chosen}
    trials = make_trials(list(cmd.robots), list(cmd.motions), list(cmd.seeds), variants)
    results, out = _run_trials(cmd, trials, f"ablate-{cmd.study}", console)
    path = write_ablation(cmd.study, ablation_table(cmd.study, chosen, results), results, out)
    console.print(path.read_text(), highlight=False)
    console.print(f"wrote {path}")
    return 0 if all(r.ok for r in results) else 1
