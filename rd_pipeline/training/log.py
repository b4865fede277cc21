"""The layout of a training folder (checkpoints and the per-iteration log) and reading it back;
no torch, so reading results stays light."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Literal

from rd_pipeline.errors import PipelineError
from rd_pipeline.files import file_sha256, write_bytes_whole

CHECKPOINT_DIR = "checkpoints"
LOG_FILE = "training_log.jsonl"

ScoreFirst = Literal["start_zero", "completion"]

SCORE_ORDER: dict[str, tuple[str, str]] = {
    "start_zero": ("start_zero_s", "completion"),
    "completion": ("completion", "start_zero_s"),
}
"""The log fields a checkpoint's score is compared by, in order, for each `ScoreFirst`."""


def checkpoint_path(folder: Path, iteration: int) -> Path:
    """Where a training folder keeps the checkpoint saved after `iteration` iterations."""
    return folder / CHECKPOINT_DIR / f"model_{iteration}.pt"


def checkpoint_iteration(path: Path) -> int:
    """The iteration a checkpoint was saved after, from its name."""
    return int(path.stem.removeprefix("model_"))


def checkpoints_by_iteration(folder: Path) -> dict[int, Path]:
    """A training folder's checkpoints keyed by the iteration each was saved after, oldest first."""
    found = {checkpoint_iteration(path): path for path in (folder / CHECKPOINT_DIR).glob("model_*.pt")}
    return dict(sorted(found.items()))


def read_training_log(folder: Path) -> list[dict]:
    """The rows of a training folder's log, one per iteration, oldest first."""
    path = folder / LOG_FILE
    if not path.is_file():
        raise PipelineError(f"{path}: no training log here")
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:
            raise PipelineError(f"{path}: line {number} is not a JSON row") from None
    return rows


def best_scored(rows: list[dict], first: ScoreFirst = "start_zero") -> dict | None:
    """The log row of the best-scored checkpoint: the longest start-zero survival, then the highest
    completion (or, with `first="completion"`, the other way round), then the latest; None when
    no row has a score."""
    scored = [row for row in rows if "start_zero_s" in row]
    order = SCORE_ORDER[first]
    return max(scored, key=lambda row: (*(row[name] for name in order), row["iteration"]), default=None)


def best_held(folder: Path, first: ScoreFirst = "start_zero", rows: list[dict] | None = None) -> dict | None:
    """The log row of the best-scored checkpoint among those the folder holds (see `best_scored`):
    a run grown from a saved state logs the whole training but holds only the checkpoints saved
    since. `rows`: the folder's log, when the caller has read it already."""
    held = checkpoints_by_iteration(folder)
    logged = read_training_log(folder) if rows is None else rows
    return best_scored([row for row in logged if row["iteration"] in held], first)


SEAL_DIR = ".seals"
"""A work folder's record of each checkpoint as saved: its sha256 and that of the log rows up to
it. Only an interrupted run reads them; a finished artifact's manifest hashes its files."""


def seal_checkpoint(folder: Path, iteration: int) -> None:
    """Record the checkpoint of `iteration` and the log it was saved with, as they are now."""
    seal = {
        "sha256": file_sha256(checkpoint_path(folder, iteration)),
        "log_sha256": _log_sha256(folder, iteration),
    }
    write_bytes_whole(_seal_path(folder, iteration), json.dumps(seal).encode())


def intact_checkpoints(folder: Path) -> tuple[Path | None, dict[Path, str]]:
    """The newest checkpoint of `folder` that matches its seal, with the log rows it was saved
    with; and what is wrong with each newer one."""
    damaged: dict[Path, str] = {}
    for iteration, path in reversed(checkpoints_by_iteration(folder).items()):
        problem = _seal_problem(folder, iteration)
        if problem is None:
            return path, damaged
        damaged[path] = problem
    return None, damaged


def _seal_problem(folder: Path, iteration: int) -> str | None:
    try:
        seal = json.loads(_seal_path(folder, iteration).read_text())
    except (OSError, ValueError):
        return "its save did not finish (no seal)"
    if file_sha256(checkpoint_path(folder, iteration)) != seal["sha256"]:
        return "its bytes changed since it was saved"
    if _log_sha256(folder, iteration) != seal["log_sha256"]:
        return f"{LOG_FILE} no longer holds the rows it was saved with"
    return None


def _log_sha256(folder: Path, iteration: int) -> str | None:
    """sha256 of the log's lines up to `iteration` (None without a log)."""
    path = folder / LOG_FILE
    if not path.is_file():
        return None
    digest = hashlib.sha256()
    for line in path.read_bytes().splitlines(keepends=True):
        if logged_iteration(line) <= iteration:
            digest.update(line)
    return digest.hexdigest()


def logged_iteration(line: str | bytes) -> float:
    """A log line's iteration; infinity for a line cut short by an interruption."""
    try:
        return json.loads(line)["iteration"]
    except (ValueError, KeyError, TypeError):
        return float("inf")


def _seal_path(folder: Path, iteration: int) -> Path:
    return folder / SEAL_DIR / f"model_{iteration}.json"
