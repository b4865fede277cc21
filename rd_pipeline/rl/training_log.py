"""The layout of a training folder (checkpoints and the per-iteration log) and reading it back;
no torch, so reading results stays light."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Literal

from rd_pipeline.errors import PipelineError

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
