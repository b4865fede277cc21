"""How a reference stands: per-second planted share and the tilt of its lowest foot."""

import dataclasses

import numpy as np
import pytest
from conftest import h1_2_dance_reference
from scipy.spatial.transform import Rotation

from rd_pipeline.motion.footing import footing_per_second

FEET = ("left_ankle_roll_link", "right_ankle_roll_link")


@pytest.fixture(scope="module")
def reference():
    return h1_2_dance_reference()


def test_standing_is_planted_and_flat_and_tiptoe_dance_is_neither(reference):
    footing = footing_per_second(reference, FEET)
    assert len(footing) == int(np.ceil(reference.duration_s))
    assert [second.start_s for second in footing[:3]] == [0, 1, 2]
    standing = footing[1:6]
    assert all(second.planted_share == 1.0 for second in standing)
    assert all(second.lowest_foot_tilt_deg < 5.0 for second in standing)
    # dance2_subject4 113-117 s is danced on the balls of the feet: the lowest foot tilted about
    # 10 degrees, and the contact labels see a planted foot in under a quarter of the frames.
    tiptoe = footing[113:117]
    assert all(second.planted_share < 0.25 for second in tiptoe)
    assert all(8.0 < second.lowest_foot_tilt_deg < 13.0 for second in tiptoe)


def test_tilt_is_the_angle_of_the_lowest_foot_from_vertical(reference):
    clip = reference.frames(0, 120)
    quat = clip.body_quat_w.copy()
    feet = [clip.body_names.index(foot) for foot in FEET]
    tilted = Rotation.from_euler("y", 20.0, degrees=True).as_quat()[[3, 0, 1, 2]]
    quat[:, feet] = tilted
    footing = footing_per_second(dataclasses.replace(clip, body_quat_w=quat), FEET)
    assert [second.lowest_foot_tilt_deg for second in footing] == [20.0, 20.0, 20.0]


def test_an_unknown_foot_is_named(reference):
    with pytest.raises(ValueError, match=r"^reference has no foot body 'left_toe_link'$"):
        footing_per_second(reference, ("left_toe_link", "right_ankle_roll_link"))
