"""What each `rd-pipeline` subcommand does: read its arguments, call the API, print the result."""

from __future__ import annotations

import dataclasses
import json
import shlex
import subprocess
import sys
from typing import TYPE_CHECKING, Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from rd_pipeline import paths
from rd_pipeline.api import sweeps, windows, workspace
from rd_pipeline.api.ablation import STUDIES, ablation_table, write_ablation
from rd_pipeline.api.windows import Selection
from rd_pipeline.artifacts.runner import StageOutcome
from rd_pipeline.cli.args import (
    DEFAULT_WINDOW_SPEED,
    Ablate,
    ExportMotion,
    FetchLafan,
    Motions,
    Plan,
    PlanOptions,
    Robots,
    Run,
    StageCommand,
    StageParams,
    Status,
    Sweep,
    View,
)
from rd_pipeline.errors import PipelineError
from rd_pipeline.profiles import profile_note
from rd_pipeline.robots.config import available_robots, load_robot_config

if TYPE_CHECKING:
    pass


def _assignments(cmd: StageParams) -> tuple[str, ...]:
    """`--set` with the shorthands `--clip`, `--backend` and `--nproc` spelled out."""
    clip = (f"train.clip={cmd.clip}",) if cmd.clip else ()
    backend = (f"train.env.backend={cmd.backend}",) if cmd.backend else ()
    ranks = (f"train.ranks={cmd.nproc}",) if cmd.nproc is not None else ()
    return cmd.set + clip + backend + ranks


def _plan(cmd: PlanOptions, console: Console, selection: Selection | None) -> workspace.Plan:
    """The plan of `cmd`; with `--window`, its clip is the window the take's reference chooses.
    The reference is made first when the stages `selection` picks include the one that makes it
    (`None`: make nothing); otherwise it must be in the store."""
    return _take_plan(cmd, cmd.robot, cmd.motion, console, selection)


def _take_plan(
    cmd: StageParams, robot: str | None, motion: str, console: Console, selection: Selection | None
) -> workspace.Plan:
    """`_plan` for a take given apart from the params (`status` walks the takes in the store)."""
    assignments = _assignments(cmd)
    plan_with = lambda extra: workspace.plan(
        robot, motion, cmd.profile, cmd.params_file, (*assignments, *extra), cmd.seed, cmd.source
    )
    if cmd.window is None:
        if cmd.window_speed is not None:
            raise PipelineError(f"--window-speed {cmd.window_speed:g} chooses among windows: give --window too")
        return plan_with(())
    quantile = DEFAULT_WINDOW_SPEED if cmd.window_speed is None else cmd.window_speed
    planned, chosen = windows.windowed_plan(plan_with, cmd.window, quantile, selection, console)
    console.print(escape(chosen.describe()), highlight=False)
    return planned


def run(cmd: Run, console: Console) -> int:
    plan = _plan(cmd, console, (cmd.from_, cmd.until, cmd.only))
    source = plan.pipeline.source
    where = f"from {source}, profile {plan.profile}, artifacts in {plan.store.root}"
    console.print(escape(f"rd-pipeline: {cmd.robot}/{cmd.motion} {where}"))
    outcomes = workspace.run(
        plan,
        start=cmd.from_,
        until=cmd.until,
        only=cmd.only,
        force=cmd.force,
        console=console,
        resume=cmd.resume,
    )
    print_summary(plan, outcomes, console)
    return 0


def plan(cmd: Plan, console: Console) -> int:
    planned = _plan(cmd, console, None)
    rows: list[dict[str, Any]] = [
        {
            "stage": entry.name,
            "key": entry.key,
            "cached": workspace.artifact(planned, entry.name) is not None,
            "params": dataclasses.asdict(entry.params),
        }
        for entry in planned.stages()
    ]
    if cmd.json:
        print(json.dumps(rows, indent=2))
        return 0
    source = planned.pipeline.source
    print(f"{cmd.robot}/{cmd.motion} from {source}, artifacts in {planned.store.root}")
    for row in rows:
        state = "cached" if row["cached"] else "to run"
        print(f"{row['stage']:<9} {row['key']}  {state}")
        for name, value in _flat(row["params"]).items():
            print(f"    {name} = {value}")
    return 0


def _flat(values: dict, prefix: str = "") -> dict[str, object]:
    """Nested params as dotted names, the way `--set` spells them."""
    flat: dict[str, object] = {}
    for name, value in values.items():
        if isinstance(value, dict):
            flat.update(_flat(value, f"{prefix}{name}."))
        else:
            flat[f"{prefix}{name}"] = value
    return flat


def print_summary(plan: workspace.Plan, outcomes: list[StageOutcome], console: Console) -> None:
    """Per stage: cached or ran, time, headline metrics; then the report to read."""
    stages = {s.name: s for s in plan.pipeline.registry}
    console.print(escape(f"summary {plan.robot}/{plan.motion}, profile {plan.profile}:"), highlight=False)
    report = None
    for outcome in outcomes:
        stage = stages[outcome.name]
        metrics = workspace.metrics(outcome.path)
        shown = "  ".join(f"{name}={_short(metrics[name])}" for name in stage.headline if name in metrics)
        state = "cached" if outcome.cached else "ran"
        console.print(escape(f"  {outcome.name:<9} {state:<6} {outcome.seconds:7.1f} s  {shown}"), highlight=False)
        if stage.report:
            report = outcome.path / stage.report
    if report is not None:
        console.print(escape(f"report: {report}"), highlight=False)
    note = profile_note(plan.profile)
    if note and any(outcome.name == "train" for outcome in outcomes):
        # The note speaks of the run that was made, `--set train.iterations=` included.
        note = note.replace("{iterations}", str(plan.pipeline.params["train"].iterations))
        console.print(f"[yellow]note:[/] {escape(note)}", highlight=False)


def _short(value: object) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def stage(cmd: StageCommand, console: Console) -> int:
    chosen = workspace.registered_stage(cmd.name)
    if chosen.per_robot and cmd.robot is None:
        raise PipelineError(f"stage '{cmd.name}' needs --robot")
    if cmd.source and chosen.source and cmd.source != chosen.source:
        raise PipelineError(f"stage '{cmd.name}' reads the {chosen.source} source, not --source {cmd.source}")
    # A head stage picks its source: `stage import` for a take that also has a BVH.
    sourced = dataclasses.replace(cmd, source=cmd.source or chosen.source)
    planned = _take_plan(sourced, cmd.robot, cmd.motion, console, (None, None, cmd.name))
    workspace.run(
        planned,
        only=cmd.name,
        force=cmd.force,
        console=console,
        resume=cmd.resume,
    )
    return 0


def status(cmd: Status, console: Console) -> int:
    root = paths.artifacts_dir()
    if cmd.robot is not None:
        load_robot_config(cmd.robot)  # an unknown robot is said as such, not as "no artifacts"
    if cmd.robot and cmd.motion:
        pairs: list[tuple[str | None, str]] = [(cmd.robot, cmd.motion)]
    else:
        pairs = workspace.pairs_in_store(root, cmd.robot, cmd.motion)
    reports: list[dict[str, Any]] = []
    if cmd.window is not None and not (cmd.robot and cmd.motion):
        raise PipelineError(f"--window {cmd.window} is chosen from one take's reference: give --robot and --motion")
    for robot, motion in pairs:
        planned = _take_plan(cmd, robot, motion, console, None)
        reports.append(
            {
                "robot": robot,
                "motion": motion,
                "source": planned.pipeline.source,
                "stages": workspace.status(planned, cmd.verify),
            }
        )
    damaged = any(row["state"] == "damaged" for report in reports for row in report["stages"])
    if cmd.json:
        print(json.dumps({"artifacts": str(root), "pipelines": reports}, indent=2))
        return 1 if damaged else 0
    if not reports:
        console.print(f"no artifacts in {escape(str(root))}")
    for report in reports:
        _print_status_table(report)
    return 1 if damaged else 0


def _print_status_table(report: dict) -> None:
    colors = {
        "cached": "green",
        "damaged": "red",
        "running": "cyan",
        "resumable": "yellow",
        "stale": "yellow",
        "missing": "red",
    }
    table = Table(title=escape(f"{report['robot'] or '(any robot)'}/{report['motion']} ({report['source']})"))
    for column in ("stage", "state", "key", "path"):
        table.add_column(column)
    for row in report["stages"]:
        state = f"[{colors[row['state']]}]{row['state']}[/]"
        where = row["path"] or ""
        reason = row.get("reason")
        shown = f"{where} ({reason})" if where and reason else reason or where
        table.add_row(row["stage"], state, row["key"] or "-", escape(shown))
    out = Console()
    if not out.is_terminal:  # piped or logged: whole paths, not a table folded at 80 columns
        out.width = 1000
    out.print(table)


def view(cmd: View, console: Console) -> int:
    from rd_pipeline.viz.recording import record_motion
    from rd_pipeline.viz.rerun_view import display_available
    from rd_pipeline.viz.tracked import TRACKED_FILE

    planned = _plan(cmd, console, (None, None, None))
    # Only the stages that make motion are needed; they are computed or taken from the cache.
    until = workspace.providing(planned, "reference")
    outcomes = workspace.run(planned, until=until, console=console)
    artifacts = {o.name: o.path for o in outcomes}
    # The tracked robot is shown when this configuration has been validated; view never trains.
    validated = workspace.artifact(planned, "validate")
    tracked = validated / TRACKED_FILE if validated else None
    if validated is None:
        validate = planned.stage("validate").key
        hint = f"no validation {validate} of these params in the store: no tracked robot (profile {planned.profile}; "
        console.print(escape(hint + "`rd-pipeline run` with the same options makes it)"), highlight=False)
    out = cmd.out
    if out is None and not display_available():
        out = planned.store.root / "views" / f"{cmd.robot}_{cmd.motion}.rrd"
        console.print("no display here (DISPLAY and WAYLAND_DISPLAY are unset): writing the recording instead")
    try:
        path = record_motion(cmd.robot, cmd.motion, artifacts, out, tracked)
    except OSError as exc:
        raise PipelineError(f"cannot write the recording {out} ({exc.strerror})") from None
    if path is not None:
        hint = shlex.quote(str(path))
        console.print(
            escape(f"wrote {path}; open it with `rerun {hint}` (pip package rerun-sdk) on a machine with a display")
        )
        if cmd.spawn:
            subprocess.Popen([sys.executable, "-m", "rerun", str(path)])
    return 0


EXPORT_FPS_RANGE = (1.0, 1000.0)
"""Frame rates `export-motion` writes: under one frame a second a clip has no frames to speak of,
and beyond a kilohertz (a physics rate) the file only grows (at 1e9 fps: terabytes)."""


def export_motion(cmd: ExportMotion, console: Console) -> int:
    from rd_pipeline.export.motion_csv import write_dataset_csv
    from rd_pipeline.export.motion_mjlab import write_mjlab_npz
    from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
    from rd_pipeline.robots import load_robot

    low, high = EXPORT_FPS_RANGE
    if cmd.fps is not None and not low <= cmd.fps <= high:
        raise PipelineError(f"--fps must be from {low:g} to {high:g} frames per second, got {cmd.fps:g}")
    planned = workspace.plan(cmd.robot, cmd.motion, cmd.profile, source=cmd.source)
    made_by = workspace.providing(planned, "reference")
    outcomes = workspace.run(planned, until=made_by, console=console)
    folder = next(o.path for o in outcomes if o.name == made_by)
    reference = ReferenceMotion.load(folder / REFERENCE_FILE)
    robot = load_robot(cmd.robot)
    missing: list[str] = []
    try:
        if cmd.format == "csv":
            fps = cmd.fps or 30.0
            frames = write_dataset_csv(reference, robot.config, cmd.out, fps)
        else:
            fps = cmd.fps or reference.fps
            frames, missing = write_mjlab_npz(reference, robot, cmd.out, fps)
    except OSError as exc:
        raise PipelineError(f"cannot write {cmd.out} ({exc.strerror})") from None
    console.print(
        escape(f"wrote {cmd.out}: {frames} frames at {fps:g} fps from {made_by} {folder.name}"), highlight=False
    )
    if missing:
        console.print(
            escape(f"mjlab's {cmd.robot} model has joints this one lacks, written as 0: {', '.join(missing)}")
        )
    return 0


def fetch_lafan(cmd: FetchLafan, console: Console) -> int:
    from rd_pipeline.motion.lafan_download import install_lafan

    target = paths.lafan_dir(existing=False)
    installed = install_lafan(cmd.zip, target, console)
    console.print(escape(f"installed {len(installed)} BVH files into {target}"))
    return 0


def robots(cmd: Robots, console: Console) -> int:
    names = available_robots()
    width = max(len(name) for name in names)
    for name in names:
        config = load_robot_config(name)
        joints = f"{len(config.joint_names):>2} joints, {len(config.policy_joints):>2} policy"
        print(f"{name:<{width}} {joints}  {config.description}")
    return 0


def motions(cmd: Motions, console: Console) -> int:
    found = paths.available_motions()
    if not found:
        raise PipelineError(f"no motions: {paths.lafan_dir()} has no BVH and RD_RETARGETED_DIR is not set or empty")
    for name, sources in found.items():
        print(f"{name:<18} {' '.join(sources)}")
    return 0


def _run_trials(cmd: Sweep, trials: list[sweeps.Trial], label: str, console: Console):
    sweeps.require_executor(cmd.executor)
    for trial in trials:  # bad parameters fail here, before any work, with one line
        sweeps.trial_plan(trial, cmd.profile)
    out = sweeps.sweep_folder(label, trials, cmd.profile)
    console.print(f"{label}: {len(trials)} trials ({cmd.executor}), results in {escape(str(out))}")

    def on_result(result: sweeps.TrialResult) -> None:
        status = "[green]ok[/]" if result.ok else f"[red]failed[/] {escape(result.error)}"
        console.print(f"trial {escape(result.trial.label)}: {status} ({result.seconds:.0f} s)")

    results = sweeps.run_sweep(
        trials,
        cmd.profile,
        cmd.executor,
        cmd.workers,
        cmd.ray_address,
        lambda trial: sweeps.validation_report(trial, cmd.profile),
        on_result,
        resume=cmd.resume,
    )
    summary = sweeps.write_summary(results, out, sweeps.SWEEP_COLUMNS)
    table = Table(title=f"{label} summary")
    for column in ("trial", "status", *sweeps.SWEEP_COLUMNS):
        table.add_column(column, overflow="fold")  # whole robot and motion names, folded, never cut
    for r in results:
        table.add_row(
            escape(r.trial.label),
            "ok" if r.ok else "failed",
            *("–" if r.metrics.get(c) is None else f"{r.metrics[c]:.2f}" for c in sweeps.SWEEP_COLUMNS),
        )
    console.print(table)
    console.print(f"wrote {escape(str(summary))}")
    return results, out


def sweep(cmd: Sweep, console: Console) -> int:
    trials = sweeps.make_trials(list(cmd.robots), list(cmd.motions), list(cmd.seeds), {"default": cmd.set})
    results, _ = _run_trials(cmd, trials, "sweep", console)
    return 0 if all(r.ok for r in results) else 1


def ablate(cmd: Ablate, console: Console) -> int:
    arms = STUDIES[cmd.study]
    unknown = [arm for arm in cmd.arms if arm not in arms]
    if unknown:
        raise PipelineError(f"--arms {unknown[0]}: not an arm of the {cmd.study} study (arms: {', '.join(arms)})")
    chosen = cmd.arms or tuple(arms)
    variants = {arm: cmd.set + arms[arm] for arm in chosen}
    trials = sweeps.make_trials(list(cmd.robots), list(cmd.motions), list(cmd.seeds), variants)
    results, out = _run_trials(cmd, trials, f"ablate-{cmd.study}", console)
    path = write_ablation(cmd.study, ablation_table(cmd.study, chosen, results), results, out)
    console.print(escape(path.read_text()), highlight=False)
    console.print(escape(f"wrote {path}"))
    return 0 if all(r.ok for r in results) else 1
