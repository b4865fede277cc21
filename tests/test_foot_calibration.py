"""A clip cut out of floor work lays the robot's feet as the whole take does.

How the human foot joint lies on its sole is learnt from the clip's own plants. ground2_subject2
145-165 s opens kneeling on the backs of the feet: learnt from every plant, the cut turned its foot
targets 94-156 degrees (median) away from the whole take's, sole flat where the human's faced up.
Learnt from the plants made standing, the two agree.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bench.retarget_variants import clips
from rd_pipeline.retarget.config import RetargetConfig, TargetShaping
from rd_pipeline.retarget.quality import FootMeshes
from rd_pipeline.retarget.targets import RetargetTargets, build_targets
from rd_pipeline.robots import Robot

FPS = 50.0
TAKE = "ground2_subject2"
CUT_S = (145, 165)


def _targets(robot: Robot, clip, shape: TargetShaping) -> RetargetTargets:
    params = RetargetConfig()
    vertices = FootMeshes.from_robot(robot).vertices
    return build_targets(clip, robot, FPS, vertices, params.contact, shape, params.body_contact)


def _median_turn_deg(robot: Robot, shape: TargetShaping) -> list[float]:
    """Per foot, the median angle between the cut's foot targets and the whole take's."""
    whole = _targets(robot, clips(TAKE, "plain")[0][1], TargetShaping())
    cut_clip = dict(clips(TAKE, "floor_cut"))[f"{TAKE} {CUT_S[0]}-{CUT_S[1]} s"]
    cut = _targets(robot, cut_clip, shape)
    start = int(CUT_S[0] * FPS)
    frames = slice(start, start + cut.n_frames)
    turns = []
    for foot in robot.config.foot_bodies:
        in_whole = Rotation.from_matrix(whole.orientations[foot][frames])
        in_cut = Rotation.from_matrix(cut.orientations[foot])
        turns.append(float(np.degrees(np.median((in_whole.inv() * in_cut).magnitude()))))
    return turns


@pytest.fixture(scope="module")
def turns(g1: Robot) -> list[float]:
    return _median_turn_deg(g1, TargetShaping())


def test_a_cut_that_opens_kneeling_turns_its_feet_as_the_whole_take(turns: list[float]) -> None:
    assert max(turns) < 10.0, turns


def test_learnt_from_every_plant_the_cut_lays_soles_flat_that_face_up(g1: Robot) -> None:
    never_standing = dataclasses.replace(TargetShaping(), standing_hips_fraction=10.0)
    assert min(_median_turn_deg(g1, never_standing)) > 60.0
