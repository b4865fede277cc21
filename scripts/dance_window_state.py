"""Keep a CPU dance-window training beyond the machine it runs on: its newest checkpoint and its
log, in the repository, and back into a store.

    python -m scripts.dance_window_state save    --clip 11:21 --iterations 6000  [--robot g1 --motion dance1_subject2]
    python -m scripts.dance_window_state restore --clip 11:21 --iterations 12000 [--robot g1 --motion dance1_subject2]
    python -m scripts.dance_window_state fork    --clip 11:21 --iterations 49000 --at 16000 [...]

The artifact store is local, and a machine can be replaced between sittings (the first 86 M-sample
run was lost that way). `save` copies the newest checkpoint of the run (finished, or interrupted in
its work folder) and its training log, gzipped, into `--state` (default
`studies/results/dance_window_state/`), replacing what was there. `restore` puts them into the work
folder of the run asked for: `studies/dance_window.py` with the same arguments then continues from
that checkpoint, as from an interrupted run (nothing in training depends on the total iterations;
the upstream stages rebuild to the same keys). `fork` gives a stage of a long run its own result
while the run goes on: the checkpoints up to `--at` (hard links) and their log rows go into the
work folder of the `--at`-iteration run, which `studies/dance_window.py --iterations <at>` then
finishes without training (export, validate). Run each with the code that trained the run on
`PYTHONPATH`: the keys are that code's.
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import shutil
import sys
from pathlib import Path

from rd_pipeline.api import workspace
from rd_pipeline.errors import PipelineError
from rd_pipeline.training.log import CHECKPOINT_DIR, LOG_FILE, checkpoints_by_iteration, seal_checkpoint
from rd_pipeline.training.runner import CONTINUED_FILE

STATE_FILE = "state.json"
"""What the saved checkpoint belongs to (robot, motion, clip, train key, iteration)."""


def main() -> None:
    parser = _parser()
    args = parser.parse_args()
    if args.action == "fork" and args.at is None:
        parser.error("fork needs --at")
    try:
        plan = _plan(args, args.iterations)
        key = plan.stage("train").key
        work = plan.store.work_folder("train", plan.robot, plan.motion, key)
        if args.action == "save":
            _save(plan, key, work, args)
        elif args.action == "restore":
            _restore(args, work)
        else:
            _fork(plan, key, work, _plan(args, args.at))
    except (PipelineError, ValueError, OSError) as exc:
        sys.exit(f"error: {exc}")


def _plan(args: argparse.Namespace, iterations: int) -> workspace.Plan:
    """The plan of the run the arguments name, trained to `iterations`."""
    overrides = (f"train.clip={args.clip}", f"train.iterations={iterations}", *args.set)
    return workspace.plan(args.robot, args.motion, args.profile, overrides=overrides, seed=args.seed)


def _run_folder(plan: workspace.Plan, key: str, work: Path) -> Path:
    """Where run `key` keeps its checkpoints: its artifact once finished, else its work folder."""
    finished = plan.store.find("train", plan.robot, plan.motion, key)
    return finished.path if finished is not None else work


def _save(plan: workspace.Plan, key: str, work: Path, args: argparse.Namespace) -> None:
    folder = _run_folder(plan, key, work)
    checkpoints = checkpoints_by_iteration(folder)
    if not checkpoints:
        raise ValueError(f"no checkpoint of train {key} in {folder}")
    iteration, newest = list(checkpoints.items())[-1]
    if args.state.exists():
        shutil.rmtree(args.state)
    args.state.mkdir(parents=True)
    shutil.copy2(newest, args.state / newest.name)
    with (folder / LOG_FILE).open("rb") as log, gzip.open(args.state / f"{LOG_FILE}.gz", "wb") as packed:
        shutil.copyfileobj(log, packed)
    state = {
        "robot": plan.robot,
        "motion": plan.motion,
        "clip": args.clip,
        "train_key": key,
        "iteration": iteration,
        "iterations": args.iterations,
        "checkpoint": newest.name,
    }
    (args.state / STATE_FILE).write_text(json.dumps(state, indent=2) + "\n")
    print(f"saved {newest.name} of train {key} to {args.state}")


def _restore(args: argparse.Namespace, work: Path) -> None:
    state_dir = args.state
    state = json.loads((state_dir / STATE_FILE).read_text())
    # The iteration count keys a run but changes nothing it trains: the saved run's key is
    # computed with the count it was saved under, whatever count it grows to now.
    saved = _plan(args, state.get("iterations", state["iteration"])).stage("train").key
    if saved != state["train_key"]:
        # Other code or arguments: the checkpoint would continue a run it never was.
        raise ValueError(
            f"{state_dir / STATE_FILE} holds a checkpoint of train {state['train_key']}, "
            f"but this code and these arguments make train {saved}: "
            "restore with the code and arguments that trained it"
        )
    if checkpoints_by_iteration(work):
        raise ValueError(f"{work} already holds checkpoints: continue it as it is")
    (work / CHECKPOINT_DIR).mkdir(parents=True, exist_ok=True)
    shutil.copy2(state_dir / state["checkpoint"], work / CHECKPOINT_DIR / state["checkpoint"])
    with gzip.open(state_dir / f"{LOG_FILE}.gz", "rb") as packed, (work / LOG_FILE).open("wb") as log:
        shutil.copyfileobj(packed, log)
    seal_checkpoint(work, state["iteration"])  # the state vouched for it; the run checks the seal
    print(f"restored {state['checkpoint']} (train {state['train_key']}) into {work}")


def _fork(plan: workspace.Plan, key: str, work: Path, stage: workspace.Plan) -> None:
    folder = _run_folder(plan, key, work)
    at = stage.pipeline.params["train"].iterations
    held = {iteration: path for iteration, path in checkpoints_by_iteration(folder).items() if iteration <= at}
    if at not in held:
        raise ValueError(f"train {key} holds no checkpoint {at} in {folder}")
    stage_key = stage.stage("train").key
    if stage.store.find("train", stage.robot, stage.motion, stage_key) is not None:
        raise ValueError(f"train {stage_key} ({at} iterations) is finished already")
    into = stage.store.work_folder("train", stage.robot, stage.motion, stage_key)
    if checkpoints_by_iteration(into):
        raise ValueError(f"{into} already holds checkpoints: finish it as it is")
    # Filled beside its name and renamed, so a fork that fails partway leaves no half-filled run.
    filling = into.with_name(f"{into.name}.forking")
    shutil.rmtree(filling, ignore_errors=True)
    (filling / CHECKPOINT_DIR).mkdir(parents=True)
    for path in held.values():
        os.link(path, filling / CHECKPOINT_DIR / path.name)
    if (folder / CONTINUED_FILE).is_file():
        shutil.copy2(folder / CONTINUED_FILE, filling / CONTINUED_FILE)
    lines = (folder / LOG_FILE).read_text().splitlines(keepends=True)
    (filling / LOG_FILE).write_text("".join(line for line in lines if json.loads(line)["iteration"] <= at))
    for iteration in held:
        seal_checkpoint(filling, iteration)
    # What a work folder without checkpoints holds is a start that trained nothing to keep.
    shutil.rmtree(into, ignore_errors=True)
    filling.rename(into)
    print(f"forked train {key} at {at} ({len(held)} checkpoints) into {into}")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("action", choices=("save", "restore", "fork"))
    parser.add_argument("--robot", default="g1")
    parser.add_argument("--motion", default="dance1_subject2")
    parser.add_argument("--clip", default="11:21")
    parser.add_argument("--profile", default="cpu")
    parser.add_argument("--iterations", type=int, required=True)
    parser.add_argument("--at", type=int, help="fork: the iteration (a checkpoint) to fork at")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--set", nargs="*", default=[], help="further overrides, as the run had them")
    parser.add_argument("--state", type=Path, default=Path("studies/results/dance_window_state"))
    return parser


if __name__ == "__main__":
    main()
