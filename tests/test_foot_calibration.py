"""A clip cut out of floor work lays the robot's feet as the whole take does.

How the human foot joint lies on its sole is learnt from the clip's own plants. ground2_subject2
145-165 s opens kneeling on the backs of the feet: learnt from every plant, the cut turned its foot
targets 94-156 degrees (median) away from the whole take's, sole flat where the human's faced up.
Learnt from the plants made standing, the two agree. A cut that never stands (ground2_subject2
at 0.8x, 93-113 s: on all fours) learns from the plants under an upright shin, and a foot with
none of those borrows the other foot's lesson.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from bench.retarget_variants import clips
from rd_pipeline.retarget.config import RetargetConfig, TargetShaping
from rd_pipeline.retarget.quality import FootMeshes
from rd_pipeline.retarget.targets import build_targets
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


def _never_standing_turn_deg(robot: Robot, shape: TargetShaping) -> list[float]:
    """Median degrees per foot between the 0.8x cut's foot targets and the whole 0.8x take's."""
    params = RetargetConfig()
    vertices = FootMeshes.from_robot(robot).vertices
    take = "ground2_subject2"
    whole = build_targets(
        clips(take, "tempo_0.8")[0][1], robot, 50.0, vertices, params.contact, TargetShaping(), params.body_contact
    )
    human = dict(clips(take, "floor_cut_tempo_0.8"))[f"{take} x0.8 93-113 s"]
    cut = build_targets(human, robot, 50.0, vertices, params.contact, shape, params.body_contact)
    frames = slice(93 * 50, 93 * 50 + cut.n_frames)
    turns = []
    for foot in robot.config.foot_bodies:
        turn = Rotation.from_matrix(whole.orientations[foot][frames]).inv() * Rotation.from_matrix(
            cut.orientations[foot]
        )
        turns.append(float(np.median(np.degrees(turn.magnitude()))))
    return turns


def test_a_cut_that_never_stands_turns_its_feet_near_the_whole_take(g1: Robot) -> None:
    assert max(_never_standing_turn_deg(g1, TargetShaping())) < 40.0
    assert min(_never_standing_turn_deg(g1, EVERY_PLANT)) > 90.0
