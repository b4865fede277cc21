"""A clip cut out of floor work lays the robot's feet as the whole take does.

How the human foot joint lies on its sole is learnt from the clip's own plants. ground2_subject2
145-165 s opens kneeling on the backs of the feet: learnt from every plant, the cut turned its foot
targets 94-156 degrees (median) away from the whole take's, sole flat where the human's faced up.
Learnt from the plants made standing, the two agree.
"""

from __future__ import annotations

import numpy as np

from rd_pipeline.retarget.config import TargetShaping
from rd_pipeline.robots import Robot
from studies.foot_calibration import EVERY_PLANT, foot_turn_from_whole_take

TAKE = "ground2_subject2"
CUT_S = (145, 165)


def _median_turn_deg(robot: Robot, shape: TargetShaping) -> np.ndarray:
    return np.median(foot_turn_from_whole_take(robot, TAKE, CUT_S, shape), axis=0)


def test_a_cut_that_opens_kneeling_turns_its_feet_as_the_whole_take(g1: Robot) -> None:
    turns = _median_turn_deg(g1, TargetShaping())
    assert turns.max() < 10.0, turns


def test_learnt_from_every_plant_the_cut_lays_soles_flat_that_face_up(g1: Robot) -> None:
    turns = _median_turn_deg(g1, EVERY_PLANT)
    assert turns.min() > 60.0, turns
