"""Running a training job as several processes (data-parallel PPO) through torchrun.

The stage process writes the job beside the work folder and starts `torchrun`, whose ranks run
`python -m rd_pipeline.training.launch JOB`: each joins the process group, trains its share, and rank 0
writes the log, the checkpoints and the outcome. The stage process follows the log for its
progress bar. On one machine torchrun runs standalone; across machines it takes its rendezvous
from its own environment variables (`PET_NNODES`, `PET_NODE_RANK`, `PET_RDZV_ENDPOINT`, ...).
"""

from __future__ import annotations

import ctypes
import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import torch

from rd_pipeline.errors import PipelineError, ShareDone
from rd_pipeline.training.distributed import join_process_group, leave_process_group
from rd_pipeline.training.log import LOG_FILE, checkpoint_iteration
from rd_pipeline.training.runner import TrainingJob, TrainingOutcome, run_job

POLL_S = 1.0
"""How often the stage process reads the log of running ranks."""

STOP_TIMEOUT_S = 60.0
"""How long torchrun gets to stop its ranks on an interrupt before it is killed (it gives them 30 s)."""

PR_SET_PDEATHSIG = 1
"""prctl(2)'s option for the signal a process gets when its parent dies."""


def job_files(work: Path) -> tuple[Path, Path, Path]:
    """The job, the outcome and the ranks' console output, beside the work folder (rank 0 may
    empty the work folder itself)."""
    stem = work.parent / work.name
    return stem.with_suffix(".job.pt"), stem.with_suffix(".outcome.pt"), stem.with_suffix(".ranks.log")


def torchrun_command(job_file: Path, ranks: int) -> list[str]:
    """`torchrun` for `ranks` processes in all: standalone on one machine, or this machine's share
    of `PET_NNODES` machines whose rendezvous torchrun reads from its environment."""
    nodes = int(os.environ.get("PET_NNODES", "1"))
    if ranks % nodes:
        raise PipelineError(f"train.ranks={ranks} does not split over PET_NNODES={nodes} machines")
    layout = [f"--nproc-per-node={ranks // nodes}"]
    if nodes == 1:
        layout.append("--standalone")
    return [sys.executable, "-m", "torch.distributed.run", *layout, "-m", __name__, str(job_file)]


def train_in_processes(job: TrainingJob, on_iteration: Callable[[dict], None]) -> TrainingOutcome:
    """Train `job` as `job.config.ranks` processes, following rank 0's log into `on_iteration`."""
    job_file, outcome_file, output_file = job_files(job.work)
    torch.save(job, job_file)
    outcome_file.unlink(missing_ok=True)
    command = torchrun_command(job_file, job.config.ranks)
    with output_file.open("w") as output:
        process = subprocess.Popen(command, stdout=output, stderr=subprocess.STDOUT)
        resumed_at = 0 if job.checkpoint is None else checkpoint_iteration(job.checkpoint)
        try:
            followed = _follow_log(job.work / LOG_FILE, process, on_iteration, resumed_at)
        except BaseException:  # Ctrl-C or SIGTERM here: no rank may outlive the key's lock
            _stop(process, STOP_TIMEOUT_S)
            raise
    machine = os.environ.get("PET_NODE_RANK", "0")
    if process.returncode == 0 and machine != "0":
        raise ShareDone(
            f"train: the ranks of machine {machine} finished; machine 0 (PET_NODE_RANK=0) writes the artifact"
        )
    if process.returncode != 0 or not outcome_file.exists():
        tail = output_file.read_text().strip().splitlines()[-1:] or ["no output"]
        raise PipelineError(
            f"train: the {job.config.ranks} training processes stopped (exit {process.returncode}) "
            f"after {followed} logged iterations; their output is in {output_file}: {tail[0]}"
        )
    outcome: TrainingOutcome = torch.load(outcome_file, weights_only=False)
    for path in (job_file, outcome_file, output_file):
        path.unlink()
    return outcome


def _stop(process: subprocess.Popen, timeout_s: float) -> None:
    """Stop torchrun and its ranks: on SIGTERM torchrun stops the ranks it started (each in a
    session of its own, out of reach of a signal to ours) and waits for them; past `timeout_s`
    it is killed, and the ranks' parent-death signal ends them."""
    process.terminate()
    try:
        process.wait(timeout_s)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def _follow_log(log: Path, process: subprocess.Popen, on_iteration: Callable[[dict], None], after: int) -> int:
    """Hand each log row of an iteration past `after` to `on_iteration`, once and in order, until
    `process` ends; returns how many.

    Each poll reads only what was appended since the last one. A resumed run first rewrites the log
    up to its checkpoint (a new file) and then logs the iterations after it again: rows are told
    apart by their iteration, so none is handed twice and none is skipped.
    """
    handed = after
    followed = 0
    tail = _LogTail(log)
    while True:
        finished = process.poll() is not None
        for row in tail.new_rows():
            if row["iteration"] <= handed:
                continue
            on_iteration(row)
            handed = row["iteration"]
            followed += 1
        if finished:
            return followed
        time.sleep(POLL_S)


class _LogTail:
    """The complete lines appended to a file since the last read; a file replaced under the same
    name is read again from its start."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.inode: int | None = None
        self.offset = 0

    def new_rows(self) -> list[dict]:
        try:
            inode = self.path.stat().st_ino
        except FileNotFoundError:
            return []
        if inode != self.inode:
            self.inode = inode
            self.offset = 0
        with self.path.open("rb") as file:
            file.seek(self.offset)
            appended = file.read()
        # A line still being written waits for the next poll.
        complete = appended[: appended.rfind(b"\n") + 1]
        self.offset += len(complete)
        return [json.loads(line) for line in complete.splitlines()]


def _rank_main(job_file: Path) -> None:
    """One rank of a data-parallel training (what torchrun starts)."""
    _die_with_parent()
    job: TrainingJob = torch.load(job_file, weights_only=False)
    ranks = join_process_group(job.config.env.device)
    # The machine's cores are shared by its ranks: each steps its physics and runs torch on its
    # share (the thread count changes no result).
    env = job.config.env
    threads = max(1, env.threads // ranks.local_world_size)
    config = dataclasses.replace(job.config, env=dataclasses.replace(env, threads=threads))
    job = dataclasses.replace(job, config=config)
    torch.set_num_threads(max(1, (os.cpu_count() or 1) // ranks.local_world_size))
    try:
        outcome = run_job(job, lambda row: None, ranks)
        if ranks.leader:
            _, outcome_file, _ = job_files(job.work)
            torch.save(outcome, outcome_file)
    finally:
        leave_process_group()


def _die_with_parent() -> None:
    """Ask Linux to send this rank SIGTERM when torchrun, its parent, dies however it dies (a
    SIGKILL leaves it no time to stop its ranks): no rank trains on as an orphan."""
    if not sys.platform.startswith("linux"):
        return
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() == 1:  # the parent died before the request
        os.kill(os.getpid(), signal.SIGTERM)


if __name__ == "__main__":
    _rank_main(Path(sys.argv[1]))
