"""A pelvis miss is explained frame by frame: a frame over the bar that the wider-ranges copy
brings within it reads as the copy's, the others still count, and frames the copy alone puts over
the bar do not."""

from __future__ import annotations

import numpy as np

from bench.retarget_variants import excused_p95

FRAMES = 1000


def _deviation(over: slice, value: float) -> np.ndarray:
    deviation = np.full(FRAMES, 0.02)
    deviation[over] = value
    return deviation


def test_frames_the_copy_brings_within_the_bar_are_excused() -> None:
    own = _deviation(slice(0, 200), 0.2)
    wider = _deviation(slice(0, 200), 0.09)
    assert excused_p95(own, wider) == 0.09


def test_frames_the_copy_leaves_over_the_bar_still_count() -> None:
    own = _deviation(slice(0, 200), 0.2)
    wider = _deviation(slice(100, 200), 0.15)
    assert excused_p95(own, wider) == 0.2


def test_frames_only_the_copy_puts_over_the_bar_are_not_misses() -> None:
    own = _deviation(slice(0, 200), 0.2)
    wider = _deviation(slice(500, 700), -0.12)
    assert np.percentile(np.abs(wider), 95.0) > 0.1
    assert excused_p95(own, wider) == 0.02
