"""`train`: reference + balanced prior -> residual-action policy, by PPO or TD3 (checkpoints, log,
learning curve)."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich.markup import escape

from rd_pipeline.artifacts.stage import Stage, StageContext
from rd_pipeline.artifacts.store import ArtifactRef
from rd_pipeline.files import open_npz
from rd_pipeline.robots.assets import model_files
from rd_pipeline.training.config import TrainConfig, clip_frames

if TYPE_CHECKING:
    from rd_pipeline.training.runner import ShorterRun, TrainingJob, TrainingOutcome

CURVE_FILE = "learning_curve.png"
PROFILE_FILE = "sampler_profile.png"


def _run(ctx: StageContext) -> dict[str, Any]:
    from rd_pipeline.training.log import best_held
    from rd_pipeline.training.runner import continued_from, training_metrics

    config: TrainConfig = ctx.params
    # Checkpoints and the log live in the work folder, which survives an interruption.
    work = ctx.work_dir or ctx.out_dir
    job, clip = _job(ctx, config, work)
    outcome = _train(ctx, job)
    rows = _into_artifact(work, ctx.out_dir)
    # The last iteration is always a scored checkpoint, so there is a best one.
    best = best_held(ctx.out_dir, rows=rows)
    assert best is not None
    stretch = f"{config.clip} s" if config.clip else "the whole take"
    title = f"{ctx.robot} {ctx.motion}, {stretch}, {config.iterations} iterations"
    _plot(rows, best, outcome, ctx.out_dir, title)
    return {
        **training_metrics(rows, outcome, config, best),
        "continued_from": continued_from(ctx.out_dir),
        "clip_frames": list(clip),
    }


def _job(ctx: StageContext, config: TrainConfig, work: Path) -> tuple[TrainingJob, tuple[int, int]]:
    """The training job for the clip of the reference, starting from the checkpoint to continue
    (an interrupted run's in `work`, or with `--resume` the longest finished shorter run's)."""
    from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
    from rd_pipeline.robots import load_robot
    from rd_pipeline.sampling.prior import PRIOR_FILE
    from rd_pipeline.training.runner import Segments, TrainingJob, clip_segments, starting_checkpoint

    robot = load_robot(ctx.robot_name)
    reference = ReferenceMotion.load(ctx.upstream["reference"].path / REFERENCE_FILE)
    with open_npz(ctx.upstream["sampling_prior"].path / PRIOR_FILE) as prior:
        segments = Segments(prior["starts"], prior["lengths"], prior["weights"])
    warn = lambda message: ctx.console.print(f"[yellow]warning:[/] {escape(message)}", highlight=False)
    start, end = clip_frames(config.clip, reference.fps, reference.n_frames, warn)
    shorter = _longest_shorter_run(ctx.shorter, config.iterations) if ctx.resume else None
    say = lambda line: ctx.console.print(line, markup=False, highlight=False)
    checkpoint = starting_checkpoint(work, ctx.restart, shorter, say)
    job = TrainingJob(
        robot,
        reference.frames(start, end),
        clip_segments(segments, start, end, reference.fps),
        config,
        work,
        checkpoint,
    )
    return job, (start, end)


def _train(ctx: StageContext, job: TrainingJob) -> TrainingOutcome:
    """Run the job in this process or as `ranks` processes, with a progress bar."""
    from rd_pipeline.training.launch import train_in_processes
    from rd_pipeline.training.log import checkpoint_iteration
    from rd_pipeline.training.runner import run_job

    first = checkpoint_iteration(job.checkpoint) if job.checkpoint else 0
    with ctx.progress(job.config.iterations, f"{job.config.algorithm.upper()} {ctx.robot}", done=first) as advance:
        status = lambda row: advance(f"reward {row['reward']:.2f}  episode {row['episode_length_s'] or 0:.2f} s")
        if job.config.ranks > 1:
            return train_in_processes(job, status)
        return run_job(job, status)


def _into_artifact(work: Path, out_dir: Path) -> list[dict]:
    """Move the work folder's checkpoints and log into the artifact; the log's rows."""
    from rd_pipeline.training.log import SEAL_DIR, read_training_log

    rows = read_training_log(work)
    # The seals guard an interrupted run; the artifact's manifest hashes its files.
    shutil.rmtree(work / SEAL_DIR, ignore_errors=True)
    if work != out_dir:
        for item in work.iterdir():
            shutil.move(str(item), out_dir / item.name)
        work.rmdir()
    return rows


def _plot(rows: list[dict], best: dict, outcome: TrainingOutcome, out_dir: Path, title: str) -> None:
    """The learning curve and the sampler's failure profile, beside the checkpoints."""
    from rd_pipeline.sampling.plots import plot_sampler_profile
    from rd_pipeline.training.plots import plot_learning_curve

    plot_learning_curve(rows, best, out_dir / CURVE_FILE, title)
    uniform = 1 / len(outcome.failure_rate)
    plot_sampler_profile(outcome.failure_rate, outcome.probabilities, uniform, out_dir / PROFILE_FILE, title)


def _longest_shorter_run(runs: tuple[ArtifactRef, ...], iterations: int) -> ShorterRun | None:
    """The finished run with the most iterations below `iterations`, if any."""
    from rd_pipeline.training.runner import ShorterRun  # torch stays unloaded until a stage runs

    below = [run for run in runs if run.manifest["params"]["iterations"] < iterations]
    if not below:
        return None
    run = max(below, key=lambda run: run.manifest["params"]["iterations"])
    return ShorterRun(run.key, run.path, run.manifest["params"]["iterations"])


def _kept_progress(work: Path) -> tuple[bool, str]:
    """The checkpoint an interrupted training kept that a rerun continues from, if any."""
    from rd_pipeline.training.log import intact_checkpoints

    intact, damaged = intact_checkpoints(work)
    broken = "; ".join(f"{path.name}: {problem}" for path, problem in damaged.items())
    if intact is None:
        return False, f"no checkpoint in {work} can be continued ({broken}); `--force` starts over"
    also = f" ({broken})" if broken else ""
    return True, f"an interrupted run kept {intact.name} in {work}{also}; `run` continues from it"


STAGE = Stage(
    name="train",
    version=7,
    description="reference + prior -> residual-action policy (multi-head PPO or TD3, segment sampler)",
    params=TrainConfig,
    provides="policy",
    run=_run,
    inputs=lambda robot, motion: model_files(robot),
    requires=("reference", "sampling_prior"),
    headline=("iterations", "best_checkpoint", "best_start_zero_s", "samples_per_s_median"),
    extends=("iterations",),
    kept_progress=_kept_progress,
)
