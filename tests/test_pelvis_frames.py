"""`bench/pelvis_frames.py` finds the human feet the targets plant on their backs: many on a
floor cut that opens kneeling, none on a dance; and it learns each sole on the whole take, so a
cut that never stands reads the same soles. Its build-free copy has no volume but the feet's and
ranges wider than G1's legs, and leaves the robot it copies as it was."""

from __future__ import annotations

import numpy as np
import pytest

from bench.pelvis_frames import planted_on_back, sole_directions, whole_take_variant
from bench.retarget_ranges import BUILD_FREE_WIDEN_RAD, build_free
from bench.retarget_variants import clips, floor_cut
from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.human import HumanMotion
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.quality import FootMeshes
from rd_pipeline.retarget.targets import RetargetTargets, build_targets
from rd_pipeline.robots import Robot, load_robot
from rd_pipeline.robots.hulls import BodyHulls

FPS = 50.0


def _targets(robot: Robot, human: HumanMotion) -> RetargetTargets:
    params = RetargetConfig()
    vertices = FootMeshes.from_robot(robot).vertices
    return build_targets(human, robot, FPS, vertices, params.contact, params.shape, params.body_contact)


def _on_back(robot: Robot, take: str, clip: HumanMotion) -> int:
    whole = clips(take, "plain")[0][1]
    soles = sole_directions(whole, _targets(robot, whole))
    return int(planted_on_back(clip, _targets(robot, clip), soles).sum())


def test_feet_planted_on_their_backs_are_found_kneeling_and_not_dancing(g1: Robot) -> None:
    kneeling = floor_cut("ground2_subject2", "ground2_subject2 145-165 s")
    dance = clips("dance1_subject1", "plain")[0][1]
    assert _on_back(g1, "ground2_subject2", kneeling) > 300
    assert _on_back(g1, "dance1_subject1", dance) == 0


def test_soles_learnt_on_takes_of_two_performers_agree(g1: Robot) -> None:
    takes = ("ground2_subject2", "fallAndGetUp2_subject3")
    soles = [sole_directions(human, _targets(g1, human)) for human in (clips(t, "plain")[0][1] for t in takes)]
    angle = np.degrees(np.arccos(np.clip(np.sum(soles[0] * soles[1], axis=1), -1.0, 1.0)))
    assert angle.max() < 15.0


def test_a_clip_that_never_stands_has_no_sole_to_learn(g1: Robot) -> None:
    crawl = floor_cut("ground2_subject3", "ground2_subject3 164-184 s")
    message = "the human never stands on the LeftFoot foot: no sole direction to learn"
    with pytest.raises(PipelineError, match=f"^{message}$"):
        sole_directions(crawl, _targets(g1, crawl))


def test_the_build_free_copy_has_no_volume_but_the_feet_and_wider_ranges(g1: Robot) -> None:
    h1 = load_robot("h1")
    own = BodyHulls.from_robot(h1)
    free = BodyHulls.from_robot(build_free(h1))
    feet = h1.config.foot_bodies
    for name, radii, points in zip(free.body_names, free.radii, free.points):
        mine = own.body_names.index(name)
        if name in feet:
            np.testing.assert_array_equal(points, own.points[mine])
        else:
            # One point per geom (a sphere of no size) where the robot has a mesh or a capsule.
            assert radii.max() < 1e-5, name
            assert len(points) < len(own.points[mine]), name
    hip = own.points[own.body_names.index("left_hip_pitch_link")]
    assert np.ptp(hip, axis=0).max() > 0.05
    knee = h1.model.joint("left_knee_joint").id
    g1_knee = g1.model.joint("left_knee_joint").id
    ankle = h1.model.joint("left_ankle_joint").id
    copy = build_free(h1).model
    np.testing.assert_allclose(
        copy.jnt_range[knee], g1.model.jnt_range[g1_knee] + [-BUILD_FREE_WIDEN_RAD, BUILD_FREE_WIDEN_RAD]
    )
    np.testing.assert_allclose(
        copy.jnt_range[ankle], h1.model.jnt_range[ankle] + [-BUILD_FREE_WIDEN_RAD, BUILD_FREE_WIDEN_RAD]
    )
    assert h1.model.jnt_range[knee][1] == pytest.approx(2.05, abs=0.01)


@pytest.mark.parametrize("variant", ["floor_cut", "floor_cut_mirror", "floor_cut_tempo_0.8"])
def test_a_floor_cut_name_says_which_take_it_was_cut_from(variant: str) -> None:
    name, _ = clips("ground2_subject2", variant)[0]
    take, *perturbed = name.rsplit(" ", 2)[0].split(" ")
    assert take == "ground2_subject2"
    assert f"floor_cut_{whole_take_variant(perturbed)}".removesuffix("_plain") == variant


def test_a_cut_name_with_an_unknown_perturbation_stops_in_one_line() -> None:
    with pytest.raises(PipelineError, match=r"^'upside down' names no perturbation \(mirrored, x<tempo>\)$"):
        whole_take_variant(["upside", "down"])
