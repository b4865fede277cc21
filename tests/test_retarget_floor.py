"""Retargeting takes that go to the floor: floor work, a fall and getting up, and a take that once collapsed.

Each test retargets a short excerpt of a real LAFAN1 take (for the G1 unless it names another
robot) and asserts the issue's bars with the whole-body ruler: no body through the floor, the
pelvis as low as the scaled human's, planted feet still, no limit, velocity or self-collision
frame, no diverged frame, a root no faster than the human's hips, and the robot tilting and
getting up when the human does.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import LAFAN_DIR
from scipy.spatial.transform import Rotation

from bench.retarget_variants import floor_cut
from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, HumanMotion, human_motion_from_bvh
from rd_pipeline.retarget.config import IkConfig, LagRepair, PelvisRepair, RetargetConfig
from rd_pipeline.retarget.quality import FootMeshes, quality_series, summarize_quality
from rd_pipeline.retarget.retarget import RetargetResult, retarget
from rd_pipeline.retarget.targets import build_targets
from rd_pipeline.retarget.tasks import position_cost_schedule
from rd_pipeline.robots import load_robot
from rd_pipeline.robots.hulls import BodyHulls

EXCERPTS = {
    # name: (take, start s, end s): floor work, a fall and getting up, and the pushes and kneeling
    # during which the G1 was once upside down for 7 s (120-127 s) while the human stayed upright.
    "floor": ("ground2_subject2", 6.0, 26.0),
    "fall": ("fallAndGetUp3_subject1", 36.0, 50.0),
    "once_collapsed": ("pushAndFall1_subject1", 115.0, 135.0),
}
LYING = {"floor", "fall"}
"""Excerpts where the human's hips come within 0.3 m of the floor."""


def _excerpt(motion: str, start_s: float, end_s: float) -> HumanMotion:
    human = human_motion_from_bvh(read_bvh(LAFAN_DIR / f"{motion}.bvh"), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
    frames = slice(int(start_s * human.fps), int(end_s * human.fps))
    return dataclasses.replace(human, pos_w=human.pos_w[frames], quat_w=human.quat_w[frames])


@pytest.fixture(scope="module", params=sorted(EXCERPTS))
def excerpt(request) -> tuple[str, RetargetResult, dict, dict]:
    motion, start_s, end_s = EXCERPTS[request.param]
    robot = load_robot("g1")
    result = retarget(_excerpt(motion, start_s, end_s), robot, RetargetConfig())
    targets = result.targets
    series = quality_series(robot, result.reference, targets.positions, targets.bodies, targets.human_pelvis)
    return request.param, result, series, summarize_quality(robot, result.reference, series)


@pytest.mark.slow
def test_the_issue_bars_hold(excerpt) -> None:
    name, _, _, quality = excerpt
    assert quality["penetration_max_mm"] <= 10.0, name
    assert quality["pelvis_height_dev_p95_m"] <= 0.10, name
    assert quality["skate_stance_mean_mm_s"] <= 20.0, name
    assert quality["joint_limit_violations"] == 0, name
    assert quality["velocity_limit_violations"] == 0, name
    assert quality["self_collision_frames"] == 0, name
    assert quality["diverged_frames"] == 0, name


@pytest.mark.slow
def test_root_is_no_faster_than_the_human(excerpt) -> None:
    name, _, _, quality = excerpt
    assert quality["root_speed_p999_m_s"] <= 1.6 * quality["human_root_speed_p999_m_s"], name


@pytest.mark.slow
def test_low_human_low_robot(excerpt) -> None:
    """Where the scaled human hips are within 0.3 m of the floor, the robot pelvis is close (no floating);
    where they are high, the robot's are too (no collapse)."""
    name, result, _, _ = excerpt
    human_z = result.targets.human_pelvis[:, 2]
    pelvis = result.reference.body_names.index("pelvis")
    robot_z = result.reference.body_pos_w[:, pelvis, 2]
    # And no collapse: where the human's hips are well up, so is the robot's pelvis.
    assert robot_z[human_z > 0.45].min() > 0.25, name
    low = human_z < 0.3
    if name not in LYING:
        return
    assert low.sum() > 50, f"{name}: the excerpt should reach the floor"
    assert np.percentile(robot_z[low] - human_z[low], 95) < 0.15, name
    assert robot_z.min() > 0.0, name


@pytest.mark.slow
def test_robot_tilts_and_rises_with_the_human(excerpt) -> None:
    """The pelvis follows the human's tilt (lying, on all fours) and stands again when the human does."""
    name, result, _, _ = excerpt
    reference = result.reference
    pelvis = reference.body_names.index("pelvis")
    robot_up = Rotation.from_quat(reference.body_quat_w[:, pelvis][:, [1, 2, 3, 0]]).apply([0.0, 0.0, 1.0])
    human_up = result.targets.orientations["pelvis"][:, :, 2]
    human_tilt = np.degrees(np.arccos(np.clip(human_up[:, 2], -1.0, 1.0)))
    robot_tilt = np.degrees(np.arccos(np.clip(robot_up[:, 2], -1.0, 1.0)))
    assert human_tilt.max() > 60.0, f"{name}: the excerpt should tilt the pelvis"
    assert np.percentile(np.abs(robot_tilt - human_tilt), 95) < 30.0, name
    # Upside down (pelvis up pointing below the horizon) only where the human is too.
    assert not np.any((robot_up[:, 2] < -0.2) & (human_up[:, 2] > 0.2)), name
    # Of the excerpts only `once_collapsed` ends with the human standing again; there the robot stands too.
    standing_again = result.targets.human_pelvis[-25:, 2] > 0.5
    assert standing_again.all() == (name == "once_collapsed"), name
    if standing_again.all():
        assert reference.body_pos_w[-25:, pelvis, 2].min() > 0.5, name


@pytest.mark.slow
def test_body_contacts_rest_on_the_floor(excerpt) -> None:
    """Knees, hands or trunk rest on the floor in every excerpt; while resting, the robot body is on it."""
    name, result, series, _ = excerpt
    targets = result.targets
    reference = result.reference
    assert targets.body_contact.any(), name
    hulls = BodyHulls.from_robot(load_robot("g1"))
    lowest = hulls.lowest_z(reference.body_pos_w, reference.body_quat_w, reference.body_names)
    columns = [hulls.body_names.index(b) for b in targets.bodies]
    resting = lowest[:, columns][targets.body_contact]
    assert np.median(resting) < 0.05, name
    assert series["penetration_m"].max() <= 0.010, name


@pytest.mark.slow
def test_a_stretch_stuck_on_the_wrong_branch_is_solved_again() -> None:
    """Solved from 61 s of ground2, where the human is down on hands and feet, the forward IK starts
    from the standing default pose and stays bent over it for about a second (pelvis far above the
    scaled hips); solved backward from where it has caught up, the stretch is not. With the lag
    repair off the ruler sees it, with it on the bars hold. (The clip's own start tries folded knees
    too, and starts from them: here it may only stand.)"""
    human = _excerpt("ground2_subject2", 61.0, 70.0)
    standing = IkConfig(start_knee_bends=(0.0,))
    unrepaired, repaired = _figures(
        human,
        "g1",
        RetargetConfig(ik=standing, repair=LagRepair(error_ratio=0.0)),
        RetargetConfig(ik=standing),
    )
    assert unrepaired[0] == 0 and repaired[0] >= 1
    assert unrepaired[1]["pelvis_height_dev_p95_m"] > 0.11
    assert repaired[1]["pelvis_height_dev_p95_m"] <= 0.10
    assert repaired[1]["keypoint_error_p95_mm"] < 0.75 * unrepaired[1]["keypoint_error_p95_mm"]
    for figure in (
        "penetration_max_mm",
        "velocity_limit_violations",
        "self_collision_frames",
        "joint_limit_violations",
    ):
        assert repaired[1][figure] == 0, figure


@pytest.mark.slow
def test_a_robot_left_lying_while_the_human_sits_up_is_solved_again() -> None:
    """H1 on ground2_subject2 75-95 s: the performer sits up from lying and the forward IK keeps
    the trunk low for seconds (181 frames diverged: keypoint error far above the clip's typical);
    solved again from both ends, nearly half of them come up. (At stage 28 the repair's stronger guide was what brought it up; since
    the pelvis is held in height along the vertical, either guide does.)"""
    human = _excerpt("ground2_subject2", 75.0, 95.0)
    unrepaired, repaired = _with_repairs(human, "h1", LagRepair(error_ratio=0.0), LagRepair())
    assert repaired[0] >= 1
    assert unrepaired[1]["diverged_frames"] > 60
    assert repaired[1]["diverged_frames"] < 0.7 * unrepaired[1]["diverged_frames"]
    assert repaired[1]["keypoint_error_p95_mm"] < 0.95 * unrepaired[1]["keypoint_error_p95_mm"]
    assert repaired[1]["skate_stance_mean_mm_s"] <= 15.0
    for figure in ("penetration_max_mm", "self_collision_frames", "joint_limit_violations"):
        assert repaired[1][figure] == 0, figure


def _with_repairs(human: HumanMotion, robot_name: str, *repairs: LagRepair) -> list[tuple[int, dict]]:
    """Per lag repair: the windows it re-solved and the ruler's figures of the retarget."""
    configs = [dataclasses.replace(RetargetConfig(), repair=repair) for repair in repairs]
    return _figures(human, robot_name, *configs)


def _figures(human: HumanMotion, robot_name: str, *configs: RetargetConfig) -> list[tuple[int, dict]]:
    """Per config: the windows the lag repair re-solved and the ruler's figures of the retarget."""
    robot = load_robot(robot_name)
    figures = []
    for config in configs:
        result = retarget(human, robot, config)
        targets = result.targets
        series = quality_series(robot, result.reference, targets.positions, targets.bodies, targets.human_pelvis)
        figures.append((result.repaired_windows, summarize_quality(robot, result.reference, series)))
    return figures


@pytest.mark.slow
def test_a_pelvis_left_on_the_hip_housings_is_solved_again_lower() -> None:
    """H1 on fallAndGetUp2_subject3 27-35 s: for a second the performer sits back on one hand,
    hips 8 cm off the floor, and H1 sits up on its hip housings, its pelvis 0.10 m higher over
    the scaled hips than it is standing. Solved again with the pelvis held harder, and kept
    because the finished feet slide no more, the pelvis comes down."""
    human = _excerpt("fallAndGetUp2_subject3", 27.0, 35.0)
    unrepaired = dataclasses.replace(RetargetConfig(), pelvis_repair=PelvisRepair(gains=()))
    (_, before), (_, after) = _figures(human, "h1", unrepaired, RetargetConfig())
    assert before["pelvis_height_dev_p95_m"] > 0.10
    assert after["pelvis_height_dev_p95_m"] <= 0.06
    assert after["skate_stance_mean_mm_s"] <= before["skate_stance_mean_mm_s"] + 0.5


@pytest.mark.slow
def test_a_lower_pelvis_that_would_drag_the_feet_is_not_kept() -> None:
    """H1 on pushAndFall1_subject4 144-152 s: the performer lies, then gets up. The stretch
    solved again with the pelvis held harder hands the get-up a posture whose planted feet
    slide (12.6 mm/s kept regardless, 4.6 as judged; 21.2 and 8.1 while the plant lock reached
    2 cm, before stage 33): judged on the finished motion, it is not kept."""
    human = _excerpt("pushAndFall1_subject4", 144.0, 152.0)
    regardless = dataclasses.replace(RetargetConfig(), pelvis_repair=PelvisRepair(skate_tolerance_m_s=10.0))
    (_, kept), (_, judged) = _figures(human, "h1", regardless, RetargetConfig())
    assert kept["skate_stance_mean_mm_s"] > 10.0
    assert judged["skate_stance_mean_mm_s"] < 7.0


@pytest.mark.slow
def test_a_stretch_whose_feet_slide_at_the_stiffest_gain_is_kept_at_a_softer_one() -> None:
    """H1-2 on the floor cut of ground2_subject2 played at 0.8 times its speed, 93-113 s: the
    performer lies with the hips off the floor and a foot planted. Held five times harder over
    the last 6 s, the pelvis comes down and the finished feet slide 15.6 -> 46.6 mm/s (judged,
    not kept); three times harder it comes down less and they slide no more, and that is kept."""
    human = floor_cut("ground2_subject2", "ground2_subject2 x0.8 93-113 s", "floor_cut_tempo_0.8")
    stiffest = dataclasses.replace(RetargetConfig(), pelvis_repair=PelvisRepair(gains=(5.0,)))
    (_, only_stiffest), (_, family) = _figures(human, "h1_2", stiffest, RetargetConfig())
    assert only_stiffest["pelvis_height_dev_p95_m"] > 0.12
    assert family["pelvis_height_dev_p95_m"] <= 0.10
    assert family["skate_stance_mean_mm_s"] <= only_stiffest["skate_stance_mean_mm_s"] + 1.0


@pytest.mark.slow
def test_a_stretch_the_ruler_reads_within_its_bar_is_left_as_solved() -> None:
    """G1 on the floor cut of ground2_subject3 at 164-184 s: near the floor the pelvis sits more
    than 0.06 m over its target, and the ruler reads it within its bar (p95 0.075 m). Its raised
    stretches are left as the IK solved them (the output is that of no repair at all); asked to
    mend any height over the median, the repair re-solves one and keeps it."""
    human = floor_cut("ground2_subject3", "ground2_subject3 164-184 s")
    robot = load_robot("g1")
    unrepaired = dataclasses.replace(RetargetConfig(), pelvis_repair=PelvisRepair(gains=()))
    any_height = dataclasses.replace(RetargetConfig(), pelvis_repair=PelvisRepair(visible_m=0.0))
    configs = (unrepaired, RetargetConfig(), any_height)
    left, default, mended = (retarget(human, robot, config).reference for config in configs)
    np.testing.assert_array_equal(default.joint_pos, left.joint_pos)
    assert np.abs(mended.joint_pos - left.joint_pos).max() > 0.1


def test_a_clip_that_opens_kneeling_starts_from_folded_knees() -> None:
    """G1 on ground2_subject3 61-65 s: the performer kneels and sits back. From the standing default
    the first frame kneels upright with the hips thrown back and the robot stays on that branch,
    its pelvis far over the sitting human's (p95 0.17 m); tried from folded knees as well, the
    clip starts there and sits on its heels. The pelvis repair is off in both: since stage 31
    it brings the standing start's pelvis down too (p95 0.078 m)."""
    human = _excerpt("ground2_subject3", 61.0, 65.0)
    best = dataclasses.replace(RetargetConfig(), pelvis_repair=PelvisRepair(gains=()))
    standing = dataclasses.replace(best, ik=IkConfig(start_knee_bends=(0.0,)))
    (_, from_standing), (_, from_best) = _figures(human, "g1", standing, best)
    assert from_standing["pelvis_height_dev_p95_m"] > 0.12
    assert from_best["pelvis_height_dev_p95_m"] <= 0.10
    assert from_best["keypoint_error_mean_mm"] < from_standing["keypoint_error_mean_mm"]


def test_a_tilted_pelvis_is_held_to_its_height_along_the_vertical() -> None:
    """The pelvis is held more closely in height than across: along its own up axis and along
    whichever axis of its target stands most upright. On ground2_subject3 66-76 s the performer sits and crawls with the hips
    tipped by about 60 degrees; weighed along the pelvis' own up axis, H1 stayed 0.135 m (p95)
    over the scaled human's hips."""
    human = _excerpt("ground2_subject3", 66.0, 76.0)
    robot = load_robot("h1")
    params = RetargetConfig()
    targets = build_targets(
        human,
        robot,
        params.fps,
        FootMeshes.from_robot(robot).vertices,
        params.contact,
        params.shape,
        params.body_contact,
    )
    costs = position_cost_schedule(targets, robot.config, params.weights)
    root = targets.bodies.index(robot.config.root_body)
    axes_up = np.abs(targets.orientations[robot.config.root_body][:, 2, :])
    tipped = axes_up[:, 0] > axes_up[:, 2]
    assert tipped.mean() > 0.9, "the hips should be tipped over most of the excerpt"
    assert np.all(costs[tipped, root, 0] > 0.6 * params.weights.root_height)
    assert np.all(costs[~tipped, root, 0] < 0.6 * params.weights.root_height)
    np.testing.assert_array_equal(costs[:, root, 2], params.weights.root_height)
    ((_, figures),) = _figures(human, "h1", params)
    assert figures["pelvis_height_dev_p95_m"] <= 0.10
    assert figures["skate_stance_mean_mm_s"] <= 15.0
    assert figures["penetration_max_mm"] == 0.0


def test_a_body_sliding_on_the_floor_keeps_its_targets_together() -> None:
    """The performer crawls 3.5 m lying on the floor (ground2_subject3 164-184 s): the pelvis
    touches the floor throughout but slides, so its target goes with the hips' instead of staying
    where the touch began (1.15 m away from them when every touch was held)."""
    robot = load_robot("g1")
    params = RetargetConfig()
    feet = FootMeshes.from_robot(robot).vertices
    human = _excerpt("ground2_subject3", 164.0, 184.0)
    targets = build_targets(human, robot, params.fps, feet, params.contact, params.shape, params.body_contact)
    pelvis, left, right = (targets.bodies.index(b) for b in ("pelvis", "left_hip_roll_link", "right_hip_roll_link"))
    hips = 0.5 * (targets.positions[:, left, :2] + targets.positions[:, right, :2])
    apart = np.linalg.norm(targets.positions[:, pelvis, :2] - hips, axis=-1)
    assert apart.max() < 0.2
    # Until it slides, the touch is held like any rest.
    assert 0 < targets.body_contact[:, pelvis].sum() < 0.5 * targets.n_frames
