"""The arguments of each `rd-pipeline` subcommand: one frozen dataclass each, read by tyro."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import tyro

DEFAULT_ROBOT = "g1"
DEFAULT_MOTION = "dance1_subject2"
DEFAULT_WINDOW_SPEED = 0.5
"""`--window` without `--window-speed`: the take's typical stretch, not its extreme."""


@dataclass(frozen=True)
class Take:
    """One robot and motion."""

    robot: str = DEFAULT_ROBOT
    """Robot (`rd-pipeline robots`)."""
    motion: str = DEFAULT_MOTION
    """Motion (`rd-pipeline motions`)."""


@dataclass(frozen=True)
class StageParams:
    """What determines the params every stage of a take's DAG gets."""

    profile: str | None = None
    """Parameter profile: smoke, cpu or paper (default: the params file's, else smoke)."""
    seed: int = 0
    """Seed for stages that draw random numbers."""
    source: str | None = None
    """Force the motion source: `bvh` (parse + retarget) or `csv` (import)."""
    clip: str | None = None
    """The part of the motion training uses, `START:END` in seconds (sets train.clip)."""
    window: int | None = None
    """A stretch of this many seconds for training, chosen by the reference's joint speed (sets
    train.clip to it; see --window-speed)."""
    window_speed: float | None = None
    """Which stretch --window takes: the one whose joint-speed p95 is nearest this quantile of the
    take's (1: the busiest; default 0.5: a typical stretch)."""
    backend: str | None = None
    """Physics backend for training, `rollout`, `cpu` or `warp` (sets train.env.backend)."""
    nproc: int | None = None
    """Training processes, data-parallel PPO launched through torchrun (sets train.ranks)."""
    set: tuple[str, ...] = ()
    """Parameter overrides, `stage.param=value`."""
    params_file: Path | None = None
    """A DVC-style params file (`params.yaml`) with a `stages:` table."""


# A dataclass orders its fields from the last base to the first: the take comes first in --help.
@dataclass(frozen=True)
class PlanOptions(StageParams, Take):
    """What determines a run's DAG: robot, motion, and the params every stage gets."""


@dataclass(frozen=True)
class Run(PlanOptions):
    """Run the DAG for one robot and motion; cached stages do no work."""

    from_: Annotated[str | None, tyro.conf.arg(name="from")] = None
    """First stage to run (parse, retarget, import, stats, prior, train, export, validate); earlier
    stages must already be cached."""
    until: str | None = None
    """Last stage to run (one of the stages above)."""
    only: str | None = None
    """Run just this stage (one of the stages above)."""
    force: bool = False
    """Recompute the selected stages even when cached (an interrupted training starts over)."""
    resume: bool = False
    """Grow a finished training that differs only in fewer iterations (an interrupted training
    continues from its checkpoints without it)."""


@dataclass(frozen=True)
class Plan(PlanOptions):
    """Show the DAG a run would execute: each stage's key, whether it is cached, its resolved params;
    runs nothing."""

    json: bool = False
    """Print a JSON list of `{"stage", "key", "cached", "params"}` instead of a table."""


@dataclass(frozen=True, kw_only=True)
class StageCommand(StageParams):
    """Run one stage (what `dvc.yaml` calls); its upstream artifacts must exist. The options that
    set a run's params (profile, clip, window, set, ...) set this stage's as they would the run's."""

    name: tyro.conf.Positional[str]
    """Stage name."""
    motion: str
    """Motion."""
    robot: str | None = None
    """Robot (not needed for robot-independent stages such as parse)."""
    force: bool = False
    """Recompute even when cached."""
    resume: bool = False
    """Grow a finished training that differs only in fewer iterations (an interrupted training
    continues from its checkpoints without it)."""


@dataclass(frozen=True)
class AnyTake:
    """A robot, a motion, or every one in the store."""

    robot: str | None = None
    """Only this robot (default: every robot with artifacts)."""
    motion: str | None = None
    """Only this motion (default: every motion with artifacts)."""


@dataclass(frozen=True)
class Status(StageParams, AnyTake):
    """Per stage: key, path and whether it is cached, stale or missing, for the params a run with
    the same options would get."""

    json: bool = False
    """Print JSON instead of a table."""
    verify: bool = False
    """Check every file's sha256 against its manifest (file sizes are always checked)."""


@dataclass(frozen=True)
class View(PlanOptions):
    """Write (or show) a rerun recording: human skeleton, robot reference and, once validated, the
    tracked robot of the sim2sim start-zero rollout, on one timeline. The options that chose a
    run's params (profile, clip, window, set, ...) choose which validation is shown."""

    out: Path | None = None
    """Write an `.rrd` file here (headless); without it a viewer is spawned."""
    spawn: bool = False
    """Also open the written file in the rerun viewer."""


@dataclass(frozen=True)
class ExportMotion:
    """Write the reference motion (from `retarget` or `import`, computed or cached) for other stacks."""

    robot: str = DEFAULT_ROBOT
    """Robot."""
    motion: str = DEFAULT_MOTION
    """Motion."""
    out: Path = Path("motion.csv")
    """File to write."""
    format: Literal["csv", "mjlab"] = "csv"
    """`csv`: the LAFAN1_Retargeting_Dataset layout (root xyz, root quaternion xyzw, joint angles; no
    header); `mjlab`: the npz of mjlab's and BeyondMimic's motion loaders."""
    fps: float | None = None
    """Frame rate of the written motion (default: 30 for csv, the dataset's; the reference's 50 for mjlab)."""
    profile: str | None = None
    """Parameter profile whose reference to export."""
    source: str | None = None
    """Force the motion source (`bvh` or `csv`)."""


@dataclass(frozen=True)
class FetchLafan:
    """Install the official lafan1.zip into `raw_lafan/` after checking its sha256."""

    zip: Path | None = None
    """A lafan1.zip already downloaded; without it the archive is downloaded."""


@dataclass(frozen=True)
class Robots:
    """List the configured robots."""


@dataclass(frozen=True)
class Motions:
    """List the motions available here and their sources."""


@dataclass(frozen=True)
class Sweep:
    """Full DAG runs over robots x motions x seeds (shared upstream computed once); a summary table at the end."""

    robots: tuple[str, ...] = (DEFAULT_ROBOT,)
    """Robots."""
    motions: tuple[str, ...] = (DEFAULT_MOTION,)
    """Motions."""
    seeds: tuple[int, ...] = (0,)
    """Training seeds."""
    profile: str | None = "smoke"
    """Parameter profile of every trial."""
    executor: Literal["local", "ray"] = "local"
    """`local`: subprocesses on this machine; `ray`: tasks on a Ray cluster (or a local Ray instance)."""
    ray_address: str | None = None
    """Address of a running Ray cluster (default: start a local one)."""
    workers: int = 2
    """Trials at a time with the local executor."""
    set: tuple[str, ...] = ()
    """Parameter overrides for every trial, `stage.param=value`."""
    resume: bool = False
    """Continue interrupted trainings from their last checkpoint (finished trials are cached anyway)."""


@dataclass(frozen=True, kw_only=True)
class Ablate(Sweep):
    """One of the paper's ablations as a sweep, reduced to its table (markdown + JSON): `residual`
    (Table r5's masks absolute / selective / hip_knee_ankle / all_legs / legs_torso / all, plus
    reference_locked) or `sampler` (uniform / distribution / failure / combined)."""

    study: tyro.conf.Positional[Literal["residual", "sampler"]]
    """Which study."""
    arms: tuple[str, ...] = ()
    """Arms to run (default: all of the study's); residual: absolute, selective, hip_knee_ankle,
    all_legs, legs_torso, all, reference_locked; sampler: uniform, distribution, failure, combined."""
