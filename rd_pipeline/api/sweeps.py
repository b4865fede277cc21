"""Sweeps: many full DAG runs (robot x motion x seed x variant), on local processes or a Ray cluster.

Upstream stages that do not depend on the seed or the variant (parse, retarget/import, stats,
prior) are computed once per (robot, motion) before the trials start; the trials then find them in
the content-addressed store. Each trial is one `rd-pipeline run` subprocess, so a crash or a bad
parameter in one trial is reported in the summary and never stops the others. With Ray, every
worker must see the same artifact folder (`RD_ARTIFACTS` on a shared file system).
"""

from __future__ import annotations

import importlib.util
import itertools
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

from rd_pipeline import paths
from rd_pipeline.api import workspace
from rd_pipeline.artifacts.keys import artifact_key
from rd_pipeline.errors import PipelineError
from rd_pipeline.evaluation.validation_report import ValidationReport

EXECUTORS = ("local", "ray")
SHARED_UNTIL = "prior"
"""The last stage whose artifact every trial of one (robot, motion) shares."""


@dataclass(frozen=True)
class Trial:
    """One full DAG run."""

    robot: str
    motion: str
    seed: int
    variant: str = "default"
    """Label of the parameter variant (an ablation arm)."""
    assignments: tuple[str, ...] = ()
    """`--set` overrides of the variant."""

    @property
    def label(self) -> str:
        return f"{self.robot}/{self.motion}/seed{self.seed}/{self.variant}"


@dataclass
class TrialResult:
    trial: Trial
    ok: bool
    seconds: float
    error: str = ""
    """Last line of the trial's error output when it failed."""
    metrics: dict = field(default_factory=dict)
    """The headline of the trial's validation report."""
    report: str = ""
    """Path of the trial's `report.json`."""


def make_trials(
    robots: list[str], motions: list[str], seeds: list[int], variants: dict[str, tuple[str, ...]] | None = None
) -> list[Trial]:
    variants = variants or {"default": ()}
    return [
        Trial(r, m, s, name, sets)
        for (name, sets), r, m, s in itertools.product(variants.items(), robots, motions, seeds)
    ]


SWEEP_COLUMNS = (
    "start_zero_survival_s",
    "zero_action_start_zero_survival_s",
    "mean_survival_s",
    "completion_pct",
    "E_g_mpbpe",
    "E_mpjpe",
)
"""Summary-table columns, from each trial's validate manifest."""


def trial_plan(trial: Trial, profile: str | None) -> workspace.Plan:
    """The plan of a trial's `rd-pipeline run` (its params are checked here, before any work)."""
    return workspace.plan(trial.robot, trial.motion, profile, overrides=trial.assignments, seed=trial.seed)


def trial_artifact(trial: Trial, profile: str | None, stage: str) -> Path | None:
    """The folder of the `stage` artifact a trial's run produced (found by its planned key), or None."""
    return workspace.artifact(trial_plan(trial, profile), stage)


def validation_report(trial: Trial, profile: str | None) -> Path | None:
    """The `report.json` a trial's run produced, or None."""
    folder = trial_artifact(trial, profile, "validate")
    return folder / "report.json" if folder else None


def sweep_folder(label: str, trials: list[Trial], profile: str | None) -> Path:
    """Where a sweep writes its summary: the same trials and profile always land in the same folder."""
    described = {"trials": [t.label for t in trials], "sets": [t.assignments for t in trials], "profile": profile}
    return paths.artifacts_dir() / "sweeps" / f"{label}-{artifact_key('sweep', 1, described, {}, {})[:8]}"


def _cli(args: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "rd_pipeline", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=os.getcwd(),
        check=False,
    )


def run_trial(trial: Trial, profile: str | None, env: dict[str, str], resume: bool = False) -> tuple[bool, float, str]:
    """(ok, seconds, last error line) of `rd-pipeline run` for one trial; `resume` continues an
    interrupted training from its last checkpoint."""
    args = ["run", "--robot", trial.robot, "--motion", trial.motion, "--seed", str(trial.seed)]
    args += ["--profile", profile] if profile else []
    args += ["--resume"] if resume else []
    args += ["--set", *trial.assignments] if trial.assignments else []
    began = time.perf_counter()
    done = _cli(args, env)
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    return done.returncode == 0, time.perf_counter() - began, (lines[-1] if lines and done.returncode else "")


def shared_upstream_args(trials: list[Trial], profile: str | None) -> list[str]:
    """The `rd-pipeline` arguments that make, once, the stages up to `SHARED_UNTIL` the `trials` of
    one take share: with the overrides every one of them has, so the artifacts are theirs."""
    first = trials[0]
    common = [item for item in first.assignments if all(item in trial.assignments for trial in trials)]
    args = ["run", "--robot", first.robot, "--motion", first.motion, "--until", SHARED_UNTIL]
    args += ["--profile", profile] if profile else []
    args += ["--set", *common] if common else []
    return args


def require_executor(executor: str) -> None:
    """Refuse an executor that does not exist or cannot be loaded, before any work."""
    if executor not in EXECUTORS:
        raise PipelineError(f"executor must be {' or '.join(EXECUTORS)}, got '{executor}'")
    if executor == "ray" and importlib.util.find_spec("ray") is None:
        raise PipelineError("--executor ray: ray is not installed; `pip install -e '.[ray]'` adds it")


def run_sweep(
    trials: list[Trial],
    profile: str | None,
    executor: str,
    workers: int,
    ray_address: str | None,
    find_report: Callable[[Trial], Path | None],
    on_result: Callable[[TrialResult], None],
    resume: bool = False,
) -> list[TrialResult]:
    """Shared upstream first (once per robot and motion), then every trial; results in trial order."""
    env = {**os.environ, "RD_ARTIFACTS": str(paths.artifacts_dir())}
    shared = sorted({(t.robot, t.motion) for t in trials})
    upstream_failed: dict[tuple[str, str], str] = {}
    for robot, motion in shared:
        done = _cli(shared_upstream_args([t for t in trials if (t.robot, t.motion) == (robot, motion)], profile), env)
        if done.returncode:
            upstream_failed[(robot, motion)] = (done.stderr.strip().splitlines() or ["failed"])[-1]
    runnable = [t for t in trials if (t.robot, t.motion) not in upstream_failed]
    if executor == "ray":
        outcomes = _run_on_ray(runnable, profile, env, ray_address, resume)
    else:
        with ThreadPoolExecutor(max(1, workers)) as pool:
            outcomes = list(pool.map(lambda t: run_trial(t, profile, env, resume), runnable))
    by_trial = dict(zip(runnable, outcomes))
    results = []
    for trial in trials:
        if (trial.robot, trial.motion) in upstream_failed:
            result = TrialResult(trial, False, 0.0, f"upstream: {upstream_failed[(trial.robot, trial.motion)]}")
        else:
            ok, seconds, error = by_trial[trial]
            result = TrialResult(trial, ok, seconds, error)
            report = find_report(trial) if ok else None
            if report is not None:
                result.report = str(report)
                result.metrics = ValidationReport.load(report.parent).headline()
        on_result(result)
        results.append(result)
    return results


def _run_on_ray(
    trials: list[Trial], profile: str | None, env: dict[str, str], address: str | None, resume: bool
) -> list:
    import ray

    ray.init(
        address=address,
        ignore_reinit_error=True,
        include_dashboard=False,
        log_to_driver=False,
        num_cpus=None if address else os.cpu_count(),
    )
    remote = ray.remote(num_cpus=1)(run_trial)
    try:
        # ray's stubs type remote functions of up to a few arguments; this one takes four.
        return ray.get([remote.remote(t, profile, env, resume) for t in trials])  # type: ignore[call-arg]
    finally:
        ray.shutdown()


def write_summary(results: list[TrialResult], out_dir: Path, columns: tuple[str, ...]) -> Path:
    """`summary.json` and `summary.md` (one row per trial) under `out_dir`."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = [
        {
            **asdict(r.trial),
            "ok": r.ok,
            "seconds": round(r.seconds, 1),
            "error": r.error,
            "report": r.report,
            **{c: r.metrics.get(c) for c in columns},
        }
        for r in results
    ]
    (out_dir / "summary.json").write_text(json.dumps(rows, indent=2) + "\n")
    header = ["robot", "motion", "seed", "variant", "status", "seconds", *columns]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in results:
        values = [
            r.trial.robot,
            r.trial.motion,
            str(r.trial.seed),
            r.trial.variant,
            "ok" if r.ok else f"failed: {r.error}",
            f"{r.seconds:.0f}",
            *(_fmt(r.metrics.get(c)) for c in columns),
        ]
        lines.append("| " + " | ".join(values) + " |")
    path = out_dir / "summary.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _fmt(value: object) -> str:
    return "–" if value is None else (f"{value:.2f}" if isinstance(value, float) else str(value))
