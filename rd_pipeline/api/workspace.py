"""Plan a (robot, motion) DAG, run any part of it, and read its artifacts.

    from rd_pipeline.api import workspace

    plan = workspace.plan("g1", "dance1_subject2", profile="cpu", overrides=("train.clip=0:10",))
    workspace.run(plan, until="train")
    log = workspace.training_log(workspace.artifact(plan, "train"))

The CLI, the sweeps and the benchmarks all go through these functions, so a plan made here has the
keys `rd-pipeline run` would compute for the same arguments.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.console import Console

from rd_pipeline import paths
from rd_pipeline.api.progress import stage_lines
from rd_pipeline.artifacts.plan import Pipeline, PlannedStage
from rd_pipeline.artifacts.runner import StageOutcome, execute
from rd_pipeline.artifacts.sources import check_motion_name, resolve_source
from rd_pipeline.artifacts.stage import Stage
from rd_pipeline.artifacts.status import stage_status
from rd_pipeline.artifacts.store import MANIFEST, ArtifactStore
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.duration import bvh_duration_s, csv_duration_s
from rd_pipeline.params import layered_params
from rd_pipeline.robots.config import load_robot_config
from rd_pipeline.stages import REGISTRY
from rd_pipeline.training.config import clip_frames
from rd_pipeline.training.log import checkpoints_by_iteration, read_training_log

if TYPE_CHECKING:
    from rd_pipeline.motion.reference import ReferenceMotion


@dataclass(frozen=True)
class Plan:
    """One (robot, motion) DAG with its params resolved, bound to an artifact store."""

    pipeline: Pipeline
    """The stages of this source and their layered param values."""
    store: ArtifactStore
    """Where its artifacts are read and written."""
    profile: str
    """The profile its params start from."""

    @property
    def robot(self) -> str | None:
        return self.pipeline.robot

    @property
    def motion(self) -> str:
        return self.pipeline.motion

    def stages(self) -> list[PlannedStage]:
        """Every stage of the chain with its typed params and key, in run order."""
        return list(self._planned)

    @cached_property
    def _planned(self) -> tuple[PlannedStage, ...]:
        # Keys hash every input file: planned once per plan, not once per artifact looked up.
        return tuple(self.pipeline.plan(self.pipeline.chain()))

    def stage(self, name: str) -> PlannedStage:
        """One planned stage by name."""
        for entry in self.stages():
            if entry.name == name:
                return entry
        names = ", ".join(entry.name for entry in self.stages())
        raise PipelineError(f"stage '{name}' is not in the {self.pipeline.source} pipeline (stages: {names})")


def plan(
    robot: str | None,
    motion: str,
    profile: str | None = None,
    params_file: Path | None = None,
    overrides: tuple[str, ...] = (),
    seed: int | None = None,
    source: str | None = None,
    store: Path | None = None,
) -> Plan:
    """Resolve the params of every stage (profile < params file < `stage.param=value` overrides) and
    the motion's source; every value is checked now, also for stages that will not run."""
    if robot is not None:
        load_robot_config(robot)  # unknown robot: one clear line before anything else
    check_motion_name(motion)
    names = [stage.name for stage in REGISTRY]
    # `seed` outranks the profile and the params file; a `stage.seed=` override outranks it.
    seeded = () if seed is None else tuple(f"{stage.name}.seed={seed}" for stage in REGISTRY if _has_seed(stage))
    profile_name, values = layered_params(profile, names, params_file, (*seeded, *overrides))
    pipeline = Pipeline(REGISTRY, robot, motion, resolve_source(robot, motion, source), values)
    _check_params(pipeline)
    return Plan(pipeline, ArtifactStore(store or paths.artifacts_dir()), profile_name)


def _has_seed(stage: Stage) -> bool:
    return "seed" in {field.name for field in dataclasses.fields(stage.params)}


def _check_params(pipeline: Pipeline) -> None:
    """Build every stage's params, which checks each value, also for stages that will not run; then
    the training control rate against the reference's fps (the policy steps once per reference
    frame). Said before any stage runs."""
    params = pipeline.params
    chain = {stage.provides: stage for stage in pipeline.chain()}
    if "reference" not in chain or "policy" not in chain:
        return
    maker = chain["reference"]
    fps = params[maker.name].fps
    trainer = chain["policy"]
    env = params[trainer.name].env
    control_hz = 1.0 / (env.physics_dt * env.decimation)
    if not math.isclose(control_hz, fps, rel_tol=1e-6):
        raise PipelineError(
            f"{trainer.name}.env.physics_dt * {trainer.name}.env.decimation give a {control_hz:g} Hz control rate, "
            f"but {maker.name}.fps is {fps:g}: the policy steps once per reference frame"
        )
    clip = params[trainer.name].clip
    if clip:
        frames = round(source_duration_s(pipeline) * fps)
        clip_frames(clip, fps, frames, warn=lambda message: None)  # the train stage says what it clamps


def source_duration_s(pipeline: Pipeline) -> float:
    """The motion's length from its source file's header or line count (no stage run)."""
    if pipeline.source == "bvh":
        return bvh_duration_s(paths.bvh_path(pipeline.motion))
    csv = paths.csv_path(pipeline.robot, pipeline.motion) if pipeline.robot else None
    assert csv is not None  # resolve_source chose csv because the file exists
    return csv_duration_s(csv, pipeline.params["import"].source_fps)


def run(
    plan: Plan,
    start: str | None = None,
    until: str | None = None,
    only: str | None = None,
    force: bool = False,
    resume: bool = False,
    console: Console | None = None,
) -> list[StageOutcome]:
    """Run the selected stages of `plan`; cached artifacts are reused without work. Each stage's
    progress is printed on `console` (standard error by default)."""
    console = console or Console(stderr=True, emoji=False)
    report = stage_lines(plan.pipeline, console)
    return execute(plan.pipeline, plan.store, (start, until, only), force, resume, report, console)


def providing(plan: Plan, role: str) -> str:
    """The name of the stage of this plan's chain that provides `role` (`reference`: retarget or import)."""
    return next(stage.name for stage in plan.pipeline.chain() if stage.provides == role)


def artifact(plan: Plan, stage: str) -> Path | None:
    """The folder of `stage`'s artifact for this plan's key, or None when it is not in the store."""
    entry = plan.stage(stage)
    robot = plan.robot if entry.stage.per_robot else None
    found = plan.store.find(stage, robot, plan.motion, entry.key)
    return found.path if found else None


def required_artifact(plan: Plan, stage: str) -> Path:
    """The folder of `stage`'s artifact for this plan's key, or one line saying it is not there."""
    folder = artifact(plan, stage)
    if folder is None:
        raise PipelineError(f"stage '{stage}' has no artifact for {plan.robot}/{plan.motion}: run it first")
    return folder


def reference(plan: Plan, stage: str | None = None) -> ReferenceMotion:
    """The whole take's reference motion in the store, as `stage` made it (default: the stage of
    this plan's chain that provides it, retarget or import)."""
    from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion  # MuJoCo loads when used

    folder = required_artifact(plan, stage or providing(plan, "reference"))
    return ReferenceMotion.load(folder / REFERENCE_FILE)


def status(plan: Plan, verify: bool = False) -> list[dict[str, Any]]:
    """Per stage: key, path and state (cached / damaged / stale / missing). A plan without a robot
    covers only the robot-independent stages."""
    pipeline = plan.pipeline
    if pipeline.robot is None:
        pipeline = dataclasses.replace(pipeline, registry=tuple(s for s in pipeline.registry if not s.per_robot))
    return stage_status(pipeline, plan.store, verify)


def pairs_in_store(root: Path, robot: str | None, motion: str | None) -> list[tuple[str | None, str]]:
    """(robot, motion) pairs with any artifact under `root`, filtered by `robot` and `motion`; robot
    None for motions that have only robot-independent artifacts."""
    found: set[tuple[str | None, str]] = set()
    for stage in REGISTRY:
        folder = root / stage.name
        pattern = "*/*" if stage.per_robot else "*"
        for path in folder.glob(pattern) if folder.is_dir() else []:
            found.add((path.parent.name, path.name) if stage.per_robot else (None, path.name))
    with_robot = {m for r, m in found if r is not None}
    pairs = [(r, m) for r, m in found if r is not None or m not in with_robot]
    pairs = [(r, m) for r, m in pairs if robot in (None, r) or r is None]
    pairs = [(r, m) for r, m in pairs if motion is None or m == motion]
    return sorted(pairs, key=lambda pair: (pair[1], pair[0] or ""))


def registered_stage(name: str) -> Stage:
    """A stage of the registry by name, or one line naming the stages that exist."""
    by_name = {stage.name: stage for stage in REGISTRY}
    if name not in by_name:
        raise PipelineError(f"unknown stage '{name}' (stages: {', '.join(by_name)})")
    return by_name[name]


def metrics(folder: Path) -> dict[str, Any]:
    """The metrics an artifact's manifest recorded."""
    return json.loads((folder / MANIFEST).read_text()).get("metrics", {})


def training_log(train: Path) -> list[dict]:
    """A train artifact's log rows, one per iteration."""
    return read_training_log(train)


def training_checkpoints(train: Path) -> dict[int, Path]:
    """A train artifact's checkpoints by iteration, oldest first."""
    return checkpoints_by_iteration(train)


def continued_runs(train: Path) -> list[Path]:
    """A train artifact and the runs it continued, oldest first, back to the first one missing from
    the store: a grown training continues the shorter run before it."""
    manifest_path = train / MANIFEST
    if not manifest_path.is_file():
        raise PipelineError(f"{train}: no {MANIFEST}; not a finished artifact")
    earlier = json.loads(manifest_path.read_text())["metrics"].get("continued_from")
    if earlier and (train.parent / earlier / MANIFEST).is_file():
        return [*continued_runs(train.parent / earlier), train]
    return [train]


def training_seconds(train: Path) -> float:
    """A train artifact's training time: the seconds of every iteration in its log. The log
    carries the iterations of every run the training continued (grown, resumed, restored from a
    saved checkpoint, or gone from the store), so no run's time is lost; scoring and start-up,
    well under 1 % of a CPU run, are not in it."""
    return sum(row["seconds"] for row in read_training_log(train))


def training_seconds_per_run(train: Path) -> dict[str, float]:
    """The seconds of the iterations each run behind `train` added, by key, oldest first. The
    oldest run `continued_runs` finds also carries the iterations of the runs before it."""
    runs = continued_runs(train)
    rows = read_training_log(train)
    per_run: dict[str, float] = {}
    done = 0
    for run in runs:
        manifest = json.loads((run / MANIFEST).read_text())
        iterations = manifest["params"]["iterations"]
        per_run[manifest["key"]] = sum(row["seconds"] for row in rows if done < row["iteration"] <= iterations)
        done = iterations
    return per_run


def available_motions() -> dict[str, list[str]]:
    """Motion name -> the sources present for it (`bvh`, `csv:<robot>`)."""
    return paths.available_motions()
