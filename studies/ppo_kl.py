"""Benchmark: how far one PPO update moves the policy, measured on a copy of a finished training.

    python -m studies.ppo_kl [--robot g1] [--motion dance1_subject2] [--clip 11:21] [--profile cpu]
        --from-iterations 21000 [--updates 20] [--lr-scales 1 0.1 0] [--out studies/results/ppo_kl.json]
        [--commit SHA]

The finished `train` artifact of that plan is hard-linked into a scratch store (the study's own
folders are never written) and continued there for `--updates` iterations, once per learning-rate
scale. At every minibatch step of each update it records rsl-rl's KL between the rollout policy
and the current one, the figure its adaptive schedule steers by (it divides the rate by 1.5 above
2 x desired KL, down to a floor of 1e-5, and multiplies it by 1.5 below half of it). A scale
multiplies the rate Adam steps with: 0 freezes the parameters, and the KL must then stay 0.
Writes `<out>` and `<out stem>.png` (median KL against the minibatch step, per scale).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import rsl_rl.algorithms.ppo as rsl_ppo
import rsl_rl.models.mlp_model as rsl_model
import torch

from bench.common import head_commit
from rd_pipeline.api import workspace


def main() -> None:
    args = _parser().parse_args()
    finished = workspace.artifact(_plan(args, args.from_iterations), "train")
    if finished is None:
        raise SystemExit(f"error: no finished {args.from_iterations}-iteration training for this plan")
    config = json.loads((finished / "manifest.json").read_text())["params"]["ppo"]
    scales = {}
    for scale in args.lr_scales:
        updates = _measure(args, finished, scale)
        scales[f"{scale:g}"] = _summary(updates)
        print(f"scale {scale:g}: KL at the last step, median {scales[f'{scale:g}']['kl_last_median']}")
    result = {
        "robot": args.robot,
        "motion": args.motion,
        "clip": args.clip,
        "from_iterations": args.from_iterations,
        "updates": args.updates,
        "desired_kl": config["desired_kl"],
        "minibatch_steps": config["learning_epochs"] * config["mini_batches"],
        "commit": args.commit or head_commit(),
        "scales": scales,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    _plot(result, args.out.with_suffix(".png"))


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--clip", default="11:21")
    parser.add_argument("--profile", default="cpu")
    parser.add_argument("--from-iterations", type=int, required=True)
    parser.add_argument("--updates", type=int, default=20)
    parser.add_argument("--lr-scales", type=float, nargs="+", default=[1.0, 0.1, 0.0])
    parser.add_argument("--out", type=Path, default=Path("studies/results/ppo_kl.json"))
    parser.add_argument("--commit", default=None, help="the commit the code ran (default: git's HEAD here)")
    return parser


def _plan(args: argparse.Namespace, iterations: int) -> workspace.Plan:
    sets = (f"train.clip={args.clip}", f"train.iterations={iterations}")
    return workspace.plan(args.robot, args.motion, args.profile, overrides=sets)


def _measure(args: argparse.Namespace, finished: Path, scale: float) -> list[dict]:
    """Per update of a continuation by `--updates` iterations: the KL at each minibatch step."""
    store = finished.parents[3]
    with tempfile.TemporaryDirectory(dir=store.parent) as scratch:
        root = Path(scratch)
        # The continuation only reads the stages before it: links, not copies of the whole store.
        for stage in store.iterdir():
            if stage.is_dir() and stage.name != "train":
                shutil.copytree(stage, root / stage.name, copy_function=os.link)
        shutil.copytree(finished, root / finished.relative_to(store), copy_function=os.link)
        os.environ["RD_ARTIFACTS"] = str(root)
        try:
            with _recorded_updates(scale) as updates:
                plan = _plan(args, args.from_iterations + args.updates)
                workspace.run(plan, resume=True, until="train")
            continued = workspace.artifact(plan, "train")
        finally:
            os.environ["RD_ARTIFACTS"] = str(store)
        if continued is None or not (continued / "continued_from.txt").exists():
            raise SystemExit("error: the copy did not continue the finished run (its key differs on this code)")
    return updates


@contextmanager
def _recorded_updates(scale: float) -> Iterator[list[dict]]:
    """rsl-rl's PPO with every update's minibatch KLs recorded and Adam's rate scaled."""
    updates: list[dict] = []
    steps: list[float] = []
    kl_divergence = rsl_model.MLPModel.get_kl_divergence
    update = rsl_ppo.PPO.update
    adam_step = torch.optim.Adam.step

    def recorded_kl(self, *args, **kwargs):
        kl = kl_divergence(self, *args, **kwargs)
        steps.append(float(kl.mean()))
        return kl

    def recorded_update(self):
        steps.clear()
        losses = update(self)
        updates.append({"kl": list(steps), "learning_rate": self.learning_rate})
        return losses

    def scaled_step(self, *args, **kwargs):
        rates = [group["lr"] for group in self.param_groups]
        for group in self.param_groups:
            group["lr"] *= scale
        try:
            return adam_step(self, *args, **kwargs)
        finally:
            for group, rate in zip(self.param_groups, rates):
                group["lr"] = rate

    rsl_model.MLPModel.get_kl_divergence = recorded_kl
    rsl_ppo.PPO.update = recorded_update
    torch.optim.Adam.step = scaled_step
    try:
        yield updates
    finally:
        rsl_model.MLPModel.get_kl_divergence = kl_divergence
        rsl_ppo.PPO.update = update
        torch.optim.Adam.step = adam_step


def _summary(updates: list[dict]) -> dict:
    by_step = [statistics.median(update["kl"][k] for update in updates) for k in range(len(updates[0]["kl"]))]
    return {
        "kl_by_step_median": [round(kl, 5) for kl in by_step],
        "kl_peak_median": round(statistics.median(max(update["kl"]) for update in updates), 5),
        "kl_last_median": round(statistics.median(update["kl"][-1] for update in updates), 5),
        "kl_last_max": round(max(update["kl"][-1] for update in updates), 5),
        "learning_rate_after_update": [update["learning_rate"] for update in updates],
    }


def _plot(result: dict, path: Path) -> None:
    figure, axes = plt.subplots(figsize=(7, 4))
    for scale, summary in result["scales"].items():
        kls = summary["kl_by_step_median"]
        axes.plot(range(len(kls)), kls, marker="o", label=f"Adam rate x {scale}")
    desired = result["desired_kl"]
    axes.axhline(2 * desired, color="grey", linestyle="--", label="schedule lowers the rate above")
    axes.axhline(desired / 2, color="grey", linestyle=":", label="schedule raises the rate below")
    axes.set_xlabel("minibatch step within one update")
    axes.set_ylabel(f"KL to the rollout policy (median of {result['updates']} updates)")
    axes.set_title(f"{result['robot']} {result['motion']} {result['clip']} s, from {result['from_iterations']} it")
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


if __name__ == "__main__":
    main()
