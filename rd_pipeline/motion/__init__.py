"""Motion I/O: BVH parsing, human motion, robot reference motions, dataset CSV import."""

from typing import Literal

Interpolation = Literal["cubic", "linear"]
"""How a resampled motion is filled between source frames."""

PLAUSIBLE_FPS = (20.0, 500.0)
"""Frame rates a motion capture file may declare: LAFAN1 is 30 fps, capture systems record 24 to
240 fps, high-speed ones up to about 480. A rate outside is a corrupt header (a `Frame Time: 10`
would stretch a 10 s take to 50 minutes), refused by the stage that reads it."""

QUATERNION_NORM_TOLERANCE = 1e-3
"""A CSV root quaternion this far from unit norm is counted as renormalised in a warning (the
dataset's are unit to 1e-6); below a norm of 0.5 it is refused."""

MIN_MOTION_S = 1.0
"""The shortest motion any source may give, and the shortest part of one a policy may train on:
one sampling segment. Shorter input is refused by the stage that reads it, with the file named."""


def too_short(what: str, frames: int, fps: float) -> str | None:
    """The one-line complaint about a motion of `frames` at `fps` shorter than `MIN_MOTION_S`, or None."""
    if frames / fps >= MIN_MOTION_S:
        return None
    return f"{what}: {frames} frames at {fps:.4g} fps is {frames / fps:.2f} s; a motion must last at least {MIN_MOTION_S:g} s"
