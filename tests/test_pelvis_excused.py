"""A pelvis miss is explained frame by frame: a frame over the bar that the wider-ranges copy
brings within it reads as the copy's, the others still count, and frames the copy alone puts over
the bar do not. Any of the robot's wider-ranges copies explains a frame: on a floor cut where
H1-2 sits at its ankle and knee stops, the copy with G1's hip and knee ranges alone does not
explain the miss, and the copy that widens the ankles too does."""

from __future__ import annotations

import numpy as np
import pytest

from bench.retarget import retarget_and_score
from bench.retarget_ranges import range_copies
from bench.retarget_variants import excused_p95, floor_cut, pelvis_deviation
from rd_pipeline.motion.human import HumanMotion
from rd_pipeline.robots import Robot, load_robot

FRAMES = 1000


def _deviation(over: slice, value: float) -> np.ndarray:
    deviation = np.full(FRAMES, 0.02)
    deviation[over] = value
    return deviation


def test_frames_the_copy_brings_within_the_bar_are_excused() -> None:
    own = _deviation(slice(0, 200), 0.2)
    wider = _deviation(slice(0, 200), 0.09)
    assert excused_p95(own, [wider]) == 0.09


def test_frames_the_copy_leaves_over_the_bar_still_count() -> None:
    own = _deviation(slice(0, 200), 0.2)
    wider = _deviation(slice(100, 200), 0.15)
    assert excused_p95(own, [wider]) == 0.2


def test_frames_only_the_copy_puts_over_the_bar_are_not_misses() -> None:
    own = _deviation(slice(0, 200), 0.2)
    wider = _deviation(slice(500, 700), -0.12)
    assert np.percentile(np.abs(wider), 95.0) > 0.1
    assert excused_p95(own, [wider]) == 0.02


def test_each_copy_explains_the_frames_it_brings_within_the_bar() -> None:
    own = _deviation(slice(0, 200), 0.2)
    first = _deviation(slice(0, 100), 0.15)
    second = _deviation(slice(100, 200), 0.15)
    assert excused_p95(own, [first]) == 0.2
    assert excused_p95(own, [second]) == 0.2
    assert excused_p95(own, [first, second]) == 0.02


def test_a_frame_two_copies_explain_reads_as_the_lower() -> None:
    own = _deviation(slice(0, 200), 0.2)
    low = _deviation(slice(0, 200), 0.04)
    high = _deviation(slice(0, 200), 0.09)
    assert excused_p95(own, [high, low]) == 0.04


def _deviation_on(robot: Robot, clip: HumanMotion) -> np.ndarray:
    result, _, _ = retarget_and_score(clip, robot)
    return pelvis_deviation(robot, result)


@pytest.mark.slow
def test_a_miss_at_the_ankle_stops_is_explained_by_the_copy_that_frees_the_ankles_too() -> None:
    h1_2 = load_robot("h1_2")
    clip = floor_cut("ground2_subject3", "ground2_subject3 61-81 s")
    own = _deviation_on(h1_2, clip)
    copies = {name: _deviation_on(copy, clip) for name, copy in range_copies(h1_2).items()}
    assert list(copies) == ["g1_legs", "widened", "g1_legs_widened"]
    assert np.percentile(np.abs(own), 95.0) > 0.12
    assert excused_p95(own, [copies["g1_legs"]]) > 0.10
    assert excused_p95(own, list(copies.values())) <= 0.10
