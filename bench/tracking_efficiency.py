"""Benchmark: samples to dance. Arms of the PPO recipe trained side by side on dance windows to
doubling sample budgets, losing arms stopped at each budget, every frozen checkpoint validated.

    python -m bench.tracking_efficiency --window g1_d1s2 --arms paper noise_0.5 noise_0.3 noise_0.1 \\
        --seeds 0 1 --rungs 1 2 4 8 [--jobs 2]        # train, prune, validate
    python -m bench.tracking_efficiency --window g1_d1s2 --report   # curves and table only

Each (window, arm, seed) is one pipeline (`--profile`, `cpu` by default; the arm's overrides; `--seed`),
grown rung by rung with `--resume`: the training of a rung continues the finished run of the
rung before, so a curve costs its longest budget only. A rung's checkpoint is the run's last,
fixed by its budget before anything is looked at; it is exported and validated (nominal and
randomized physics, `VALIDATE`). Which arms go on is decided by synchronous successive halving:
after every live arm has run a rung, the best 1/eta by train's own score at that checkpoint
(start-zero survival on randomized physics from a seed of its own, mean over seeds) go on, never
by the validation figures this bench reports.

Writes `bench/results/tracking_efficiency/<window>/`: `runs/<arm>_seed<k>_<M>M.json` (samples,
hours, train's score, the validation's figures, the train and validate keys, the commit),
`curves.png` and `table.md` (per arm and budget the figures and the verdict, then the bar,
samples to `--threshold` and each rung's cost); with `--pictures`, `pictures/` (the start-zero
rollout of each arm and seed at the last rung beside its reference, filmstrip and video).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from bench.common import head_commit, training_hours
from rd_pipeline.api import windows, workspace
from rd_pipeline.errors import PipelineError
from rd_pipeline.evaluation.validation_report import ValidationReport
from rd_pipeline.training.log import read_training_log


@dataclass(frozen=True)
class Window:
    """A stretch of a take to learn: a fixed clip, or the take's 10 s window at the median joint
    speed of its windows (what `rd-pipeline run --window 10 --window-speed 0.5` trains)."""

    robot: str
    motion: str
    source: str
    """`bvh`: retargeted by this project; `csv`: the dataset's retargeting."""
    clip: str | None = None
    """start:end seconds; None: the median-speed 10 s window."""

    def resolved(self, profile: str) -> Window:
        if self.clip is not None:
            return self
        whole = workspace.plan(self.robot, self.motion, profile, source=self.source)
        workspace.run(whole, until=workspace.providing(whole, "reference"))
        return replace(self, clip=windows.speed_window(whole, 10, 0.5).clip)


WINDOWS = {
    # The window of the earlier studies (studies/results/dance_window*.json).
    "g1_d1s2": Window("g1", "dance1_subject2", "bvh", "11:21"),
    "g1_d1s3": Window("g1", "dance1_subject3", "bvh"),
    "h1_2_d1s1": Window("h1_2", "dance1_subject1", "bvh"),
}


PPO = "train.algorithm=ppo"
"""The PPO arms name their learner: the `cpu` profile trains TD3 since it won here."""

ARMS: dict[str, tuple[str, ...]] = {
    "paper": (PPO,),
    # Initial action noise: the paper's 0.894 times the action scale down to MimicKit's scale.
    "noise_0.5": (PPO, "train.ppo.init_noise_std=0.5"),
    "noise_0.3": (PPO, "train.ppo.init_noise_std=0.3"),
    "noise_0.1": (PPO, "train.ppo.init_noise_std=0.1"),
    # The untrained residual policy at zero action, a small held noise (MimicKit's G1 tracker).
    "output_0.01": (PPO, "train.ppo.init_output_gain=0.01"),
    "mimickit_noise": (
        PPO,
        "train.ppo.init_output_gain=0.01",
        "train.ppo.init_noise_std=0.05",
        "train.ppo.learn_noise_std=false",
    ),
    # Action scale (the anchors' 0.25 * effort / kp per joint is 0.07-0.55 rad).
    "action_scale_0.5": (PPO, "train.env.actions.scale=0.5"),
    # The anchors' lenient, height-only end-effector terminations while training.
    "height_terminations": (PPO, "train.env.terminations.motion_far_height_only=true"),
    # Reference joints 0.1 and 0.5 s ahead in the actor's observation besides the next step's.
    "future_frames": (PPO, "train.env.observations.ref_future_steps=5,25"),
    # The sampler: uniform segments; failure credited to every visited segment.
    "sampler_uniform": (PPO, "train.sampler.mode=uniform"),
    "failure_visited": (PPO, "train.sampler.failure_credit=visited"),
    # PPO's update: fewer epochs, a lower learning rate, no entropy bonus, smaller networks.
    "epochs_2": (PPO, "train.ppo.learning_epochs=2"),
    "lr_3e-4": (PPO, "train.ppo.learning_rate=0.0003"),
    "entropy_0": (PPO, "train.ppo.entropy_coef=0.0"),
    "net_256": (PPO, "train.ppo.hidden_dims=256,128,64"),
    # The second learner: off-policy TD3 (FastTD3's recipe at CPU batch sizes), same environment.
    "td3": ("train.algorithm=td3",),
    # TD3 looking ahead: at 4 and 8 M samples its rollouts from the window's start end at the
    # reference's fastest hand moves, which the next step's reference alone does not announce.
    "td3_future_frames": ("train.algorithm=td3", "train.env.observations.ref_future_steps=5,25"),
}
"""Arm -> its `--set` overrides on the `cpu` profile (each lever of PPO's recipe, one at a time, and TD3)."""

VALIDATE = (
    "validate.randomized.seeds=10001,10002",
    "validate.randomized.models_per_seed=2",
    "validate.other_physics.enabled=false",
    "validate.render.enabled=false",
)
"""A lighter validation per rung (2 randomized seeds, no other physics, no pictures), fixed
before any run; the frozen checkpoints of `frozen_checkpoints.md` have the full one."""

RESULTS = Path("bench/results/tracking_efficiency")


def main() -> None:
    args = _parser().parse_args()
    window = WINDOWS[args.window].resolved(args.profile)
    folder = RESULTS / (args.window if args.profile == "cpu" else f"{args.window}_{args.profile}")
    folder.mkdir(parents=True, exist_ok=True)
    if args.pictures:
        _pictures(args, window, folder / "pictures")
    elif not args.report:
        _study(args, window, folder)
    rows = _rows(folder)
    _table(rows, folder / "table.md", args.eta, args.threshold)
    _curves(rows, window, folder / "curves.png")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split(".")[0])
    parser.add_argument("--window", choices=WINDOWS, default="g1_d1s2")
    parser.add_argument("--arms", nargs="+", choices=ARMS, default=list(ARMS))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    parser.add_argument("--rungs", nargs="+", type=float, default=[1, 2, 4, 8], help="budgets in M samples")
    parser.add_argument("--eta", type=int, default=2, help="1/eta of the arms go on at each rung")
    parser.add_argument(
        "--jobs",
        type=int,
        default=2,
        help="pipelines at once; their threads split the cores and enter the train key, so a study "
        "grown in a later sitting keeps its --jobs (else it trains from scratch)",
    )
    parser.add_argument(
        "--profile", default="cpu", help="cpu (2-16 cores) or paper (a GPU: --jobs 1, rungs of 10s of M)"
    )
    parser.add_argument("--report", action="store_true", help="only redraw the table and the curves")
    parser.add_argument(
        "--threshold", type=float, default=2.5, help="start-zero (s) every seed must reach, for samples to threshold"
    )
    parser.add_argument(
        "--pictures", action="store_true", help="filmstrips of the trained --arms and --seeds at the last of --rungs"
    )
    return parser


def _study(args: argparse.Namespace, window: Window, folder: Path) -> None:
    """Synchronous successive halving over the arms, rung by rung. Runs already in the store are
    cached, so a later sitting with more rungs redoes no training and comes to the same verdicts
    before it goes on."""
    live = list(args.arms)
    for rung in args.rungs:
        jobs = [(window, arm, seed, rung, args) for arm in live for seed in args.seeds]
        with ThreadPoolExecutor(args.jobs) as pool:
            rows = list(pool.map(lambda job: _run(*job), jobs))
        _record(folder, rows)
        live = sorted(_survivors(rows, args.eta))


def _survivors(rows: list[dict[str, Any]], eta: int) -> set[str]:
    """The arms of one rung that go on: the best 1/eta (at least one) by train's score, the mean
    over seeds. Every arm is judged against the whole rung (Optuna's successive-halving pruner is
    asynchronous: the first arm it judges at a rung always goes on, which made it unfit here)."""
    by_arm = {arm: [row for row in rows if row["arm"] == arm] for arm in sorted({row["arm"] for row in rows})}
    # Equal scores keep the arms' alphabetical order (the sort is stable), so a tie goes the same way every run.
    ranked = sorted(by_arm, key=lambda arm: -_mean(by_arm[arm], "train_score_s"))
    return set(ranked[: max(1, len(ranked) // eta)])


def _iterations(window: Window, arm: str, rung: float, args: argparse.Namespace) -> tuple[int, int]:
    """(iterations, checkpoint_every) of a rung: whole multiples of the first rung's iterations,
    so every rung is the one before grown (`--resume`) and ends on a checkpoint."""
    plan = workspace.plan(window.robot, window.motion, args.profile, overrides=ARMS[arm], source=window.source)
    per_iteration = plan.pipeline.params["train"].samples_per_iteration
    first = round(args.rungs[0] * 1e6 / per_iteration)
    return first * round(rung / args.rungs[0]), first


def _sets(window: Window, arm: str, rung: float, args: argparse.Namespace) -> tuple[str, ...]:
    iterations, every = _iterations(window, arm, rung, args)
    cores = max(1, (os.cpu_count() or 1) // args.jobs)
    return (
        f"train.clip={window.clip}",
        f"train.iterations={iterations}",
        f"train.checkpoint_every={every}",
        f"train.env.threads={cores}",
        *ARMS[arm],
        *VALIDATE,
    )


def _run(window: Window, arm: str, seed: int, rung: float, args: argparse.Namespace) -> dict[str, Any]:
    """Train (growing the rung before), export and validate one arm and seed at one budget."""
    sets = _sets(window, arm, rung, args)
    print(f"{arm} seed {seed}: {rung:g} M samples", flush=True)
    _pipeline(window, seed, sets, args, f"{arm} seed {seed} at {rung:g} M", resume=True)
    plan = workspace.plan(window.robot, window.motion, args.profile, overrides=sets, seed=seed, source=window.source)
    return _row(plan, arm, seed, rung)


def _pipeline(
    window: Window, seed: int, sets: tuple[str, ...], args: argparse.Namespace, label: str, *, resume: bool
) -> None:
    """One `rd-pipeline run` of the window in a child process, its threads split by `--jobs`; a
    failure ends the bench with the child's last line, prefixed by `label`."""
    take = ("--robot", window.robot, "--motion", window.motion, "--source", window.source)
    command = [sys.executable, "-m", "rd_pipeline", "run", *take, "--profile", args.profile, "--seed", str(seed)]
    if resume:
        command.append("--resume")
    env = {**os.environ, "OMP_NUM_THREADS": str(max(1, (os.cpu_count() or 1) // args.jobs))}
    done = subprocess.run([*command, "--set", *sets], env=env, capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"{label}: {done.stderr.strip().splitlines()[-1]}")


def _pictures(args: argparse.Namespace, window: Window, folder: Path) -> None:
    """Each arm and seed's checkpoint at the last rung validated again with pictures (a rung's
    own validation renders none, so the bench's figures stay as they were): the filmstrip and the
    video of its start-zero rollout beside the reference, into `folder`. Trains nothing."""
    folder.mkdir(exist_ok=True)
    rung = args.rungs[-1]
    for arm in args.arms:
        for seed in args.seeds:
            label = f"{arm} seed {seed} at {rung:g} M"
            sets = (*_sets(window, arm, rung, args), "validate.render.enabled=true")
            plan = workspace.plan(
                window.robot, window.motion, args.profile, overrides=sets, seed=seed, source=window.source
            )
            try:
                workspace.required_artifact(plan, "train")
            except PipelineError as error:
                raise SystemExit(f"{label}: {error}") from None
            print(f"{arm} seed {seed}: pictures at {rung:g} M samples", flush=True)
            _pipeline(window, seed, sets, args, label, resume=False)
            validate = workspace.required_artifact(plan, "validate")
            for name in ("filmstrip.png", "rollout.mp4"):
                shutil.copy(validate / name, folder / f"{arm}_seed{seed}_{rung:g}M_{name}")


def _row(plan: workspace.Plan, arm: str, seed: int, rung: float) -> dict[str, Any]:
    train = workspace.required_artifact(plan, "train")
    validate = workspace.required_artifact(plan, "validate")
    last = read_training_log(train)[-1]
    report = ValidationReport.load(validate)
    randomized = report.protocols["randomized"]["policy"]
    zero = report.protocols["randomized"]["zero_action"]
    return {
        "arm": arm,
        "seed": seed,
        "rung_m": rung,
        "samples": int(json.loads((train / "manifest.json").read_text())["metrics"]["samples"]),
        **training_hours(train),
        "train_score_s": last["start_zero_s"],
        "nominal_start_zero_s": report.start_zero_survival_s,
        "nominal_mean_s": report.mean_survival_s,
        "nominal_zero_action_mean_s": report.zero_action_mean_survival_s,
        "randomized_start_zero_s": randomized["start_zero_s"]["mean"],
        "randomized_mean_s": randomized["mean_survival_s"]["mean"],
        "randomized_zero_action_mean_s": zero["mean_survival_s"]["mean"],
        "tracked_pct": report.tracked_pct,
        "train_key": plan.stage("train").key,
        "validate_key": plan.stage("validate").key,
        "commit": head_commit(),
    }


def _record(folder: Path, rows: list[dict[str, Any]]) -> None:
    """One file per arm, seed and rung (a later sitting rewrites it with the same figures)."""
    runs = folder / "runs"
    runs.mkdir(exist_ok=True)
    for row in rows:
        name = f"{row['arm']}_seed{row['seed']}_{row['rung_m']:g}M.json"
        (runs / name).write_text(json.dumps(row, indent=1) + "\n")


def _rows(folder: Path) -> list[dict[str, Any]]:
    return [json.loads(path.read_text()) for path in sorted((folder / "runs").glob("*.json"))]


BAR = {"nominal_start_zero_s": 9.5, "nominal_mean_s": 4.5}
"""The issue's bar for G1 dance1_subject2 11-21 s: both on nominal physics, on every seed."""


def _by_arm(rows: list[dict[str, Any]]) -> dict[str, dict[float, list[dict[str, Any]]]]:
    """arm -> rung -> its seeds' rows."""
    grouped: dict[str, dict[float, list[dict[str, Any]]]] = {}
    for row in rows:
        grouped.setdefault(row["arm"], {}).setdefault(row["rung_m"], []).append(row)
    return grouped


def _mean(rows: list[dict[str, Any]], field: str) -> float:
    return sum(row[field] for row in rows) / len(rows)


def _verdict(rows: list[dict[str, Any]], arm: str, rung: float, eta: int) -> str:
    """Whether `arm` went on from `rung`, judged against every arm of the rung."""
    at_rung = [row for row in rows if row["rung_m"] == rung]
    if len({row["arm"] for row in at_rung}) < 2:
        return ""
    return "goes on" if arm in _survivors(at_rung, eta) else "stopped"


def _table(rows: list[dict[str, Any]], path: Path, eta: int, threshold: float) -> None:
    """Per arm and budget: the seeds' mean figures, hours, train's score and the verdict; then
    the bar, each arm's samples to `threshold` and what each rung's verdicts cost."""
    fields = ("nominal_start_zero_s", "nominal_mean_s", "randomized_start_zero_s", "randomized_mean_s")
    lines = [
        "| arm | M samples | seeds | "
        + " | ".join(fields)
        + " | zero action mean (nominal) | train score s | hours | verdict |",
        "|---" * (len(fields) + 7) + "|",
    ]
    for arm, rungs in _by_arm(rows).items():
        for rung, seeds in sorted(rungs.items()):
            figures = " | ".join(f"{_mean(seeds, field):.2f}" for field in fields)
            hours = sum(row["wall_h"] for row in seeds)
            verdict = _verdict(rows, arm, rung, eta)
            zero = _mean(seeds, "nominal_zero_action_mean_s")
            score = _mean(seeds, "train_score_s")
            lines.append(
                f"| {arm} | {rung:g} | {len(seeds)} | {figures} | {zero:.2f} | {score:.2f} | {hours:.2f} | {verdict} |"
            )
    met = [
        f"{arm} at {rung:g} M"
        for arm, rungs in _by_arm(rows).items()
        for rung, seeds in sorted(rungs.items())
        if _every_seed_meets(seeds, BAR)
    ]
    lines += [
        "",
        f"Bar (nominal start-zero >= 9.5 s and fixed-grid mean >= 4.5 s on every seed): {', '.join(met) or 'not met'}",
        "",
        f"Samples to threshold (nominal start-zero >= {threshold:g} s on every seed, the first budget that reaches it):",
        "",
        *_samples_to_threshold(rows, threshold),
        "",
        "What each rung's verdict cost (every run's training up to that budget, at its median iteration):",
        "",
        *_costs(rows),
    ]
    path.write_text("\n".join(lines) + "\n")


def _every_seed_meets(seeds: list[dict[str, Any]], bars: dict[str, float]) -> bool:
    """Whether every seed's row reaches every field's bar."""
    return all(row[field] >= bar for row in seeds for field, bar in bars.items())


def _samples_to_threshold(rows: list[dict[str, Any]], threshold: float) -> list[str]:
    """Per arm: its first budget whose every seed holds the window `threshold` seconds from its
    start on nominal physics, or the largest budget it ran without reaching it."""
    lines = []
    for arm, rungs in _by_arm(rows).items():
        reached = [
            rung
            for rung, seeds in sorted(rungs.items())
            if _every_seed_meets(seeds, {"nominal_start_zero_s": threshold})
        ]
        if reached:
            hours = _mean(rungs[reached[0]], "wall_h")
            lines.append(f"- {arm}: {reached[0]:g} M samples, {hours:.2f} h a seed")
        else:
            lines.append(f"- {arm}: not within {max(rungs):g} M samples")
    return lines


def _costs(rows: list[dict[str, Any]]) -> list[str]:
    """Per rung: the arms judged there and the machine hours every run had cost up to it."""
    lines = []
    for rung in sorted({row["rung_m"] for row in rows}):
        so_far: dict[tuple[str, int], dict[str, Any]] = {}
        for row in sorted((row for row in rows if row["rung_m"] <= rung), key=lambda row: row["rung_m"]):
            so_far[(row["arm"], row["seed"])] = row  # a run's hours grow with its budget
        hours = sum(row["wall_h_at_median_iteration"] for row in so_far.values())
        arms = len({row["arm"] for row in rows if row["rung_m"] == rung})
        judged = f"{arms} arm{'' if arms == 1 else 's'} judged"
        lines.append(f"- {rung:g} M samples: {judged}, {hours:.2f} h of the machine so far")
    return lines


def _curves(rows: list[dict[str, Any]], window: Window, path: Path) -> None:
    """Fixed-grid mean and start-zero survival against samples (log axis), nominal and
    randomized, each arm's seeds as points and their mean as a line, zero action dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    panels = (
        ("nominal_mean_s", "nominal_zero_action_mean_s", "fixed-grid mean, nominal (s)"),
        ("nominal_start_zero_s", None, "start-zero, nominal (s)"),
        ("randomized_mean_s", "randomized_zero_action_mean_s", "fixed-grid mean, randomized (s)"),
        ("randomized_start_zero_s", None, "start-zero, randomized (s)"),
    )
    figure, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels) + 2.0, 3.6))
    # One colour per arm, the same in every figure (the default cycle repeats after ten).
    palette = plt.get_cmap("tab20").colors
    colors = {arm: palette[k % len(palette)] for k, arm in enumerate(ARMS)}
    millions = [row["samples"] / 1e6 for row in rows] or [1.0]
    for axis, (field, zero, title) in zip(axes, panels):
        for arm, rungs in _by_arm(rows).items():
            budgets = sorted(rungs)
            samples = [_mean(rungs[b], "samples") / 1e6 for b in budgets]
            means = [_mean(rungs[b], field) for b in budgets]
            axis.plot(samples, means, marker="o", color=colors.get(arm), label=arm)
            for budget in budgets:
                dots = [row[field] for row in rungs[budget]]
                axis.scatter([_mean(rungs[budget], "samples") / 1e6] * len(dots), dots, color=colors.get(arm), s=8)
        if zero is not None and rows:
            axis.axhline(_mean(rows, zero), color="grey", linestyle="--", label="zero action")
        axis.set_xscale("log")
        # Budgets a rung apart differ by a factor of 2; one rung alone still gets a readable axis.
        axis.set_xlim(min(millions) / 1.5, max(millions) * 1.5)
        budgets = sorted({row["rung_m"] for row in rows})
        axis.set_xticks(budgets, [f"{budget:g}" for budget in budgets])
        axis.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        axis.set_xlabel("M samples")
        axis.set_title(title, fontsize=10)
    handles, labels = axes[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="center right", fontsize=8)
    figure.suptitle(f"{window.robot} {window.motion} {window.clip} s ({window.source}): survival against samples")
    figure.tight_layout(rect=(0.0, 0.0, 0.88, 1.0))
    figure.savefig(path, dpi=110)
    plt.close(figure)


if __name__ == "__main__":
    main()
