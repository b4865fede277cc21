"""`train`: reference + balanced prior -> residual-action PPO policy (checkpoints, log, learning curve)."""

from __future__ import annotations

import shutil
from typing import TYPE_CHECKING, Any

from rich.markup import escape

from rd_pipeline.artifacts.stage import Stage, StageContext
from rd_pipeline.artifacts.store import ArtifactRef
from rd_pipeline.files import open_npz
from rd_pipeline.rl.training_config import TrainConfig, clip_frames
from rd_pipeline.robots.assets import model_files

if TYPE_CHECKING:
    from rd_pipeline.rl.runner import ShorterRun

CURVE_FILE = "learning_curve.png"
PROFILE_FILE = "sampler_profile.png"


def _run(ctx: StageContext) -> dict[str, Any]:
    from rd_pipeline.motion.reference import REFERENCE_FILE, ReferenceMotion
    from rd_pipeline.rl.launch import train_in_processes
    from rd_pipeline.rl.runner import (
        Segments,
        TrainingJob,
        clip_segments,
        continued_from,
        run_job,
        starting_checkpoint,
        training_metrics,
    )
    from rd_pipeline.rl.trainer import plot_learning_curve
    from rd_pipeline.rl.training_log import best_scored, checkpoint_iteration, read_training_log
    from rd_pipeline.robots import load_robot
    from rd_pipeline.sampling.plots import plot_sampler_profile
    from rd_pipeline.sampling.prior import PRIOR_FILE

    config: TrainConfig = ctx.params
    robot = load_robot(ctx.robot_name)
    reference = ReferenceMotion.load(ctx.upstream["reference"].path / REFERENCE_FILE)
    with open_npz(ctx.upstream["sampling_prior"].path / PRIOR_FILE) as prior:
        segments = Segments(prior["starts"], prior["lengths"], prior["weights"])
    warn = lambda message: ctx.console.print(f"[yellow]warning:[/] {escape(message)}", highlight=False)
    start, end = clip_frames(config.clip, reference.fps, reference.n_frames, warn)
    # Checkpoints and the log live in the work folder, which survives an interruption.
    work = ctx.work_dir or ctx.out_dir
    shorter = _longest_shorter_run(ctx.shorter, config.iterations) if ctx.resume else None
    say = lambda line: ctx.console.print(line, markup=False, highlight=False)
    checkpoint = starting_checkpoint(work, ctx.restart, shorter, say)
    job = TrainingJob(
        robot, reference.frames(start, end), clip_segments(segments, start, end), config, work, checkpoint
    )
    first = checkpoint_iteration(checkpoint) if checkpoint else 0
    with ctx.progress(config.iterations, f"PPO {ctx.robot}", done=first) as advance:
        status = lambda row: advance(f"reward {row['reward']:.2f}  episode {row['episode_length_s'] or 0:.2f} s")
        if config.ranks > 1:
            outcome = train_in_processes(job, status)
        else:
            outcome = run_job(job, status)
    rows = read_training_log(work)
    if work != ctx.out_dir:
        for item in work.iterdir():
            shutil.move(str(item), ctx.out_dir / item.name)
        work.rmdir()
    plot_learning_curve(rows, ctx.out_dir / CURVE_FILE)
    uniform = 1 / len(outcome.failure_rate)
    plot_sampler_profile(outcome.failure_rate, outcome.probabilities, uniform, ctx.out_dir / PROFILE_FILE)
    # The last iteration is always a scored checkpoint, so there is a best one.
    best = best_scored(rows)
    assert best is not None
    return {
        **training_metrics(rows, outcome, config, best),
        "continued_from": continued_from(ctx.out_dir),
        "clip_frames": [start, end],
    }


def _longest_shorter_run(runs: tuple[ArtifactRef, ...], iterations: int) -> ShorterRun | None:
    """The finished run with the most iterations below `iterations`, if any."""
    from rd_pipeline.rl.runner import ShorterRun  # torch stays unloaded until a stage runs

    below = [run for run in runs if run.manifest["params"]["iterations"] < iterations]
    if not below:
        return None
    run = max(below, key=lambda run: run.manifest["params"]["iterations"])
    return ShorterRun(run.key, run.path, run.manifest["params"]["iterations"])


STAGE = Stage(
    name="train",
    version=5,
    description="reference + prior -> residual-action PPO policy (multi-head critic, segment sampler)",
    params=TrainConfig,
    provides="policy",
    run=_run,
    inputs=lambda robot, motion: model_files(robot),
    requires=("reference", "sampling_prior"),
    headline=("iterations", "best_checkpoint", "best_start_zero_s", "samples_per_s_median"),
    extends=("iterations",),
)
