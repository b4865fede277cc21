"""Robot configs load in MuJoCo and Pinocchio, agree with each other, and bad configs say what is wrong."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from conftest import LAFAN_DIR, PROJECT, ROBOT_ASSETS

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, human_motion_from_bvh
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.retarget import retarget
from rd_pipeline.robots import available_robots, load_pinocchio_model, load_robot, load_robot_config
from rd_pipeline.robots.model import check_against_model

EXPECTED = {"g1": (23, 23), "g1_29dof": (29, 29), "h1": (19, 19), "h1_2": (27, 21)}
RESIDUAL_JOINTS = {
    "g1": ["left_hip_pitch_joint", "left_knee_joint", "right_hip_pitch_joint", "right_knee_joint"],
    "g1_29dof": ["left_hip_pitch_joint", "left_knee_joint", "right_hip_pitch_joint", "right_knee_joint"],
    "h1": ["left_hip_pitch_joint", "left_knee_joint", "right_hip_pitch_joint", "right_knee_joint"],
    "h1_2": ["left_hip_pitch_joint", "left_knee_joint", "right_hip_pitch_joint", "right_knee_joint"],
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_config_matches_spec_table(name: str) -> None:
    robot = load_robot(name)
    n_joints, n_policy = EXPECTED[name]
    assert len(robot.config.joint_names) == n_joints == robot.model.nu
    assert len(robot.config.policy_joints) == n_policy
    residual = [robot.config.policy_joints[i] for i in robot.config.residual_indices]
    assert residual == RESIDUAL_JOINTS[name]
    assert np.all(robot.config.kp > 0) and np.all(robot.config.effort_limit > 0)
    lo, hi = robot.joint_range.T
    assert np.all((robot.config.default_pos >= lo) & (robot.config.default_pos <= hi))


def test_h1_2_wrists_are_outside_the_policy() -> None:
    config = load_robot_config("h1_2")
    held = [j for j in config.joint_names if j not in config.policy_joints]
    assert held == [f"{side}_wrist_{axis}_joint" for side in ("left", "right") for axis in ("roll", "pitch", "yaw")]


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_mujoco_and_pinocchio_agree(name: str) -> None:
    robot = load_robot(name)
    pin_model = load_pinocchio_model(robot.config)
    pin_data = pin_model.createData()
    # Pinocchio joint 0 is the universe, 1 the free flyer.
    assert list(pin_model.names[2:]) == list(robot.config.joint_names)
    data = mujoco.MjData(robot.model)
    rng = np.random.default_rng(7)
    lo, hi = robot.joint_range.T
    bodies = sorted(set(robot.config.tracking_bodies) | set(robot.config.foot_bodies))
    worst = 0.0
    for _ in range(25):
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        base = rng.uniform(-1, 1, size=3)
        joints = rng.uniform(lo, hi)
        data.qpos[:3], data.qpos[3:7] = base, quat
        data.qpos[robot.qpos_indices] = joints
        mujoco.mj_kinematics(robot.model, data)
        q = np.concatenate([base, quat[[1, 2, 3, 0]], joints])
        pin.framesForwardKinematics(pin_model, pin_data, q)
        for body in bodies:
            pin_pos = pin_data.oMf[pin_model.getFrameId(body)].translation
            worst = max(worst, float(np.linalg.norm(pin_pos - data.xpos[robot.body_ids[body]])))
    assert worst < 1e-3


def _broken_config(tmp_path: Path, name: str, old: str, new: str) -> Path:
    source = Path(load_robot_config(name).source)
    text = source.read_text()
    assert old in text
    path = tmp_path / f"{name}.toml"
    path.write_text(text.replace(old, new, 1))
    return path


def test_missing_body_is_named(tmp_path: Path) -> None:
    path = _broken_config(tmp_path, "g1", '"left_hip_roll_link", "left_knee_link"', '"left_hip_link", "left_knee_link"')
    config = load_robot_config("g1", path)
    with pytest.raises(PipelineError) as error:
        check_against_model(config, load_robot("g1").model)
    assert str(error.value).startswith(f"{path}: bodies.tracking names body 'left_hip_link', which is not in the model")


def test_a_keypoint_the_rewards_do_not_track_is_named(tmp_path: Path) -> None:
    path = _broken_config(tmp_path, "h1_2", 'keypoints = ["torso_link"', 'keypoints = ["head_link"')
    with pytest.raises(PipelineError) as error:
        load_robot_config("h1_2", path)
    assert str(error.value) == f"{path}: bodies.keypoints names 'head_link', which is not in bodies.tracking"


def test_joint_order_mismatch_is_named(tmp_path: Path) -> None:
    path = _broken_config(
        tmp_path, "h1", '"left_hip_yaw_joint", "left_hip_roll_joint"', '"left_hip_roll_joint", "left_hip_yaw_joint"'
    )
    with pytest.raises(
        PipelineError, match=r"joints.order\[0\] is 'left_hip_roll_joint' but actuator 0 drives 'left_hip_yaw_joint'"
    ):
        check_against_model(load_robot_config("h1", path), load_robot("h1").model)


def test_uncovered_joint_pattern_is_named(tmp_path: Path) -> None:
    path = _broken_config(tmp_path, "h1", '"torso_joint" = 300.0', '"torso_x" = 300.0')
    with pytest.raises(PipelineError, match=r"joints.kp has no pattern matching joint 'torso_joint'"):
        load_robot_config("h1", path)


def test_a_retarget_range_without_the_default_pose_is_named(tmp_path: Path) -> None:
    path = _broken_config(tmp_path, "h1", '"*_hip_pitch_joint" = [-inf, 1.5]', '"*_hip_pitch_joint" = [0.5, 1.5]')
    with pytest.raises(PipelineError) as error:
        check_against_model(load_robot_config("h1", path), load_robot("h1").model)
    assert str(error.value) == (
        f"{path}: joints.retarget_range leaves 'left_hip_pitch_joint' [0.5, 1.5] within the model's range,"
        " which does not hold its default_pos -0.1"
    )


def test_a_malformed_retarget_range_is_named(tmp_path: Path) -> None:
    path = _broken_config(tmp_path, "h1", '"*_hip_pitch_joint" = [-inf, 1.5]', '"*_hip_pitch_joint" = [1.5, -1.0]')
    with pytest.raises(PipelineError) as error:
        load_robot_config("h1", path)
    assert str(error.value) == (
        f'{path}: joints.retarget_range."*_hip_pitch_joint" must be [lower, upper] with lower < upper, got [1.5, -1.0]'
    )


def test_the_retarget_range_narrows_the_model_range_where_it_says() -> None:
    robot = load_robot("h1_2")
    names = robot.config.joint_names
    narrowed = robot.retarget_range != robot.joint_range
    hips = ["left_hip_pitch_joint", "left_hip_roll_joint", "right_hip_pitch_joint", "right_hip_roll_joint"]
    assert [names[j] for j in np.flatnonzero(narrowed.any(axis=1))] == hips
    pitch = names.index("right_hip_pitch_joint")
    roll = names.index("right_hip_roll_joint")
    np.testing.assert_allclose(robot.joint_range[[pitch, roll]], [[-3.14, 2.5], [-3.14, 0.43]], atol=0.005)
    np.testing.assert_allclose(robot.retarget_range[[pitch, roll]], [[-3.14, 1.5], [-1.57, 0.43]], atol=0.005)


def test_unknown_robot() -> None:
    with pytest.raises(PipelineError, match=r"unknown robot 'g2'.*available: g1, g1_29dof, h1, h1_2"):
        load_robot_config("g2")


def test_assets_resolve_from_variable(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("RD_ROBOT_ASSETS", str(tmp_path))
    from rd_pipeline.robots.assets import asset_path

    with pytest.raises(PipelineError, match=r"g1_description/g1_23dof.xml: robot model file not found"):
        asset_path("g1_description/g1_23dof.xml")


def test_a_robot_the_toolkit_has_never_seen_is_a_config_and_a_model(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """H1 with every joint renamed (`*_joint` -> `*_hinge`), its model and config in a folder of the
    user's: it loads from RD_ROBOT_CONFIGS and retargets a shared take exactly as H1 does."""
    original = ROBOT_ASSETS / "h1_description" / "mjcf" / "h1.xml"
    meshes = original.parent.parent / "meshes"
    model = tmp_path / "biped.xml"
    xml = original.read_text().replace('meshdir="../meshes"', f'meshdir="{meshes}"')
    model.write_text(xml.replace('_joint"', '_hinge"'))
    config = (PROJECT / "robots" / "h1.toml").read_text().replace('_joint"', '_hinge"')
    config = config.replace('name = "h1"', 'name = "biped"').replace(
        'mjcf = "h1_description/mjcf/h1.xml"', f'mjcf = "{model}"'
    )
    configs = tmp_path / "robots"
    configs.mkdir()
    (configs / "biped.toml").write_text(config)
    monkeypatch.setenv("RD_ROBOT_CONFIGS", str(configs))
    assert "biped" in available_robots() and "h1" in available_robots()
    biped = load_robot("biped")
    assert biped.config.joint_names[3] == "left_knee_hinge"
    assert biped.config.kp[3] == load_robot("h1").config.kp[3]  # patterns renamed with the joints
    human = human_motion_from_bvh(read_bvh(LAFAN_DIR / "dance1_subject2.bvh"), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
    excerpt = dataclasses.replace(human, pos_w=human.pos_w[300:450], quat_w=human.quat_w[300:450])  # 10-15 s
    ours = retarget(excerpt, biped, RetargetConfig()).reference
    theirs = retarget(excerpt, load_robot("h1"), RetargetConfig()).reference
    assert ours.joint_names == tuple(name.replace("_joint", "_hinge") for name in theirs.joint_names)
    assert np.array_equal(ours.joint_pos, theirs.joint_pos) and np.array_equal(ours.root_pos, theirs.root_pos)


@pytest.mark.parametrize(
    ("old", "new", "said"),
    [
        (
            "residual_indices = [0, 3, 6, 9]",
            'residual_indices = [0, "3", 6, 9]',
            "joints.residual_indices must be a list of whole numbers, got '3' in it",
        ),
        (
            "residual_indices = [0, 3, 6, 9]",
            "residual_indices = [0, true, 6, 9]",
            "joints.residual_indices must be a list of whole numbers, got True in it",
        ),
        (
            '["left_knee_link", "right_knee_link"]',
            '["left_knee_link", "right_knee_link", "pelvis"]',
            "collision.pairs must hold pairs of two body names, got ['left_knee_link', 'right_knee_link', 'pelvis']",
        ),
        (
            '"*_knee_joint" = 150.0',
            '"*_knee_joint" = true',
            'joints.kp."*_knee_joint" must be a finite number, got True',
        ),
        ('"*_knee_joint" = 150.0', '"*_knee_joint" = -150.0', 'joints.kp."*_knee_joint" must be positive, got -150.0'),
        ('"*_knee_joint" = 5.0', '"*_knee_joint" = -5.0', 'joints.kd."*_knee_joint" must be non-negative, got -5.0'),
        ('policy = "all"', 'policy = "some"', """joints.policy must be "all" or a list of names, got 'some'"""),
    ],
)
def test_a_robot_toml_of_the_wrong_types_or_signs_is_one_line(tmp_path: Path, old: str, new: str, said: str) -> None:
    """Each once loaded as something else (true as 1.0, "some" as the joints 's', 'o', ...) or raised."""
    path = _broken_config(tmp_path, "g1", old, new)
    with pytest.raises(PipelineError) as error:
        load_robot_config("g1", path)
    assert str(error.value) == f"{path}: {said}"
