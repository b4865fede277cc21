"""How long a source motion is, read from its header (BVH) or its line count (CSV) without parsing
it: what planning needs to check a clip against the motion before any stage runs."""

from __future__ import annotations

from pathlib import Path

from rd_pipeline.errors import PipelineError


def bvh_duration_s(path: Path) -> float:
    """`Frames` x `Frame Time` of a BVH file's MOTION header."""
    frames = None
    frame_time = None
    try:
        with path.open(encoding="utf-8", errors="replace") as lines:
            for line in lines:
                key, _, value = line.strip().partition(":")
                if key == "Frames":
                    frames = int(value)
                elif key == "Frame Time":
                    frame_time = float(value)
                    break
    except (OSError, ValueError) as exc:
        raise PipelineError(f"{path}: cannot read the BVH header ({exc})") from None
    if frames is None or frame_time is None:
        raise PipelineError(f"{path}: no 'Frames:' and 'Frame Time:' header")
    return frames * frame_time


def csv_duration_s(path: Path, fps: float) -> float:
    """Rows of a dataset CSV at `fps`."""
    try:
        with path.open("rb") as lines:
            rows = sum(1 for line in lines if line.strip())
    except OSError as exc:
        raise PipelineError(f"{path}: cannot be read ({exc.strerror})") from None
    return rows / fps
