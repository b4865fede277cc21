"""How much a reference moves: per-second joint speed and a take's windows chosen by it."""

import numpy as np
import pytest
from conftest import h1_2_dance_reference

from rd_pipeline.motion.activity import joint_speed_p95_per_second, speed_windows, window_at_speed_quantile


@pytest.fixture(scope="module")
def reference():
    return h1_2_dance_reference()


def test_per_second_speed_sees_the_standing_start_and_end(reference):
    per_second = joint_speed_p95_per_second(reference)
    assert len(per_second) == int(np.ceil(reference.duration_s))
    # dance2_subject4 opens and closes standing still: a few seconds under 0.5 rad/s at each end.
    assert max(per_second[1:6]) < 0.5
    assert max(per_second[-8:]) < 0.6
    assert np.median(per_second) > 4.0


def test_the_top_speed_quantile_is_the_fastest_ten_seconds(reference):
    window = window_at_speed_quantile(reference, 10, 1.0)
    assert (window.start_s, window.end_s, window.clip) == (193, 203, "193:203")
    frames = np.abs(reference.joint_vel[193 * 50 : 203 * 50])
    assert window.joint_speed_p95 == pytest.approx(np.percentile(frames, 95), abs=1e-3)
    shifted = np.abs(reference.joint_vel[0:500])
    assert window.joint_speed_p95 > np.percentile(shifted, 95)


def test_a_window_longer_than_the_take_is_refused(reference):
    with pytest.raises(ValueError, match=r"^a 300 s window does not fit a 225.7 s reference$"):
        speed_windows(reference, 300)


def test_the_median_speed_window_is_a_typical_stretch_of_dance(reference):
    windows = speed_windows(reference, 10)
    assert [(w.start_s, w.end_s) for w in windows[:2]] == [(0, 10), (1, 11)]
    assert len(windows) == int(reference.duration_s) - 10 + 1
    speeds = np.array([w.joint_speed_p95 for w in windows])
    typical = window_at_speed_quantile(reference, 10, 0.5)
    # Nearest the median of the take's 216 windows, and far from both the standing ends and the peak.
    assert abs(typical.joint_speed_p95 - np.median(speeds)) == pytest.approx(np.abs(speeds - np.median(speeds)).min())
    assert np.percentile(speeds, 40) < typical.joint_speed_p95 < np.percentile(speeds, 60)
    assert 20 < typical.start_s < 190
    assert window_at_speed_quantile(reference, 10, 1.0) == max(windows, key=lambda w: w.joint_speed_p95)
    assert window_at_speed_quantile(reference, 10, 0.0).joint_speed_p95 == speeds.min()
    with pytest.raises(ValueError, match=r"^speed quantile 1.5 is outside \[0, 1\]$"):
        window_at_speed_quantile(reference, 10, 1.5)
