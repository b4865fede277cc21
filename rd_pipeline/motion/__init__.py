"""Motion I/O: BVH parsing, human motion, robot reference motions, dataset CSV import."""

MIN_MOTION_S = 1.0
"""The shortest motion any source may give, and the shortest part of one a policy may train on:
one sampling segment. Shorter input is refused by the stage that reads it, with the file named."""


def too_short(what: str, frames: int, fps: float) -> str | None:
    """The one-line complaint about a motion of `frames` at `fps` shorter than `MIN_MOTION_S`, or None."""
    if frames / fps >= MIN_MOTION_S:
        return None
    return f"{what}: {frames} frames at {fps:.4g} fps is {frames / fps:.2f} s; a motion must last at least {MIN_MOTION_S:g} s"
