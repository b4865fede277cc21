"""Retargeting quality metrics: on the real dataset, and on hand-built motions with known answers."""

from __future__ import annotations

import dataclasses
import json

import mujoco
import numpy as np
import pytest
from conftest import RETARGETED_DIR
from scipy.spatial.transform import Rotation

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.reference import ReferenceMotion, reference_from_joint_trajectory
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.retarget.floor import FloorLimit, SupportCandidates
from rd_pipeline.retarget.quality import FootMeshes, QualityThresholds, quality_series, retarget_quality
from rd_pipeline.robots import Robot, load_robot
from rd_pipeline.robots.config import available_robots
from rd_pipeline.robots.hulls import BodyHulls, hull_vertices, mesh_points_in_body
from rd_pipeline.robots.model import collision_geoms

KEYS = {
    "frames",
    "fps_frames_per_s",
    "penetration_max_mm",
    "penetration_p95_mm",
    "penetration_deepest_body",
    "feet_penetration_max_mm",
    "feet_penetration_p95_mm",
    "pelvis_height_dev_p95_m",
    "skate_stance_mean_mm_s",
    "joint_limit_violations",
    "range_limited_frames",
    "range_limited_joints",
    "velocity_limit_violations",
    "self_collision_frames",
    "jerk_mean",
    "keypoint_error_mean_mm",
    "keypoint_error_p95_mm",
    "keypoint_error_max_mm",
    "diverged_frames",
    "root_speed_p999_m_s",
    "human_root_speed_p999_m_s",
    "planted_foot_turn_p95_deg",
}

# G1 left arm swung in across the chest: the elbow sinks into the torso (found by a grid search over the
# shoulder and elbow joints; no other configured pair touches).
ELBOW_IN_TORSO = {"left_shoulder_pitch_joint": 0.25, "left_shoulder_roll_joint": -1.0, "left_elbow_joint": 0.0}


@pytest.fixture(scope="module")
def g1_dance(g1) -> tuple[ReferenceMotion, dict]:
    path = RETARGETED_DIR / "g1" / "dance1_subject2.csv"
    reference = import_retargeted_csv(path, g1, 30.0, 50.0, "cubic", ContactThresholds()).reference
    return reference, retarget_quality(g1, reference)


def _hand_built(robot: Robot, joint_pos: np.ndarray, fps: float = 50.0) -> ReferenceMotion:
    """A motion standing still in the air (feet clear of the floor) with the given joint trajectory."""
    n_frames = joint_pos.shape[0]
    root_pos = np.tile([0.0, 0.0, 1.0], (n_frames, 1))
    root_quat = np.tile([1.0, 0.0, 0.0, 0.0], (n_frames, 1))
    return reference_from_joint_trajectory(
        robot, fps, root_pos, root_quat, joint_pos, np.zeros((n_frames, 2), dtype=bool)
    )


def _standing(robot: Robot, n_frames: int) -> np.ndarray:
    return np.tile(robot.config.default_pos, (n_frames, 1))


def test_dataset_feet_sink_and_skate(g1_dance) -> None:
    reference, quality = g1_dance
    assert set(quality) == KEYS
    json.dumps(quality)  # plain Python numbers only
    assert quality["frames"] == reference.n_frames == 6575
    assert quality["fps_frames_per_s"] is None and quality["keypoint_error_mean_mm"] is None
    assert quality["feet_penetration_max_mm"] > 20.0
    assert 0.0 < quality["feet_penetration_p95_mm"] <= quality["feet_penetration_max_mm"]
    # Whole-body penetration is never less than the feet's (the G1 feet collide through sole spheres,
    # the feet-only figure uses the visual mesh a viewer sees).
    assert quality["penetration_max_mm"] > 20.0
    assert quality["skate_stance_mean_mm_s"] > 100.0


def test_penetration_matches_full_mesh_in_mujoco(g1, g1_dance) -> None:
    """The hull-vertex shortcut gives the same lowest point as every vertex of the posed MuJoCo geom."""
    reference, quality = g1_dance
    lowest = FootMeshes.from_robot(g1).lowest_z(reference.body_pos_w, reference.body_quat_w, reference.body_names)
    frame, foot = np.unravel_index(np.argmin(lowest), lowest.shape)
    model = g1.model
    data = mujoco.MjData(model)
    data.qpos[:3], data.qpos[3:7] = reference.root_pos[frame], reference.root_quat[frame]
    data.qpos[g1.qpos_indices] = reference.joint_pos[frame]
    mujoco.mj_kinematics(model, data)
    body = g1.body_ids[g1.config.foot_bodies[foot]]
    geom = next(g for g in range(model.ngeom) if model.geom_bodyid[g] == body and model.geom_dataid[g] >= 0)
    mesh = model.geom_dataid[geom]
    vertices = model.mesh_vert[model.mesh_vertadr[mesh] : model.mesh_vertadr[mesh] + model.mesh_vertnum[mesh]]
    world_z = (vertices @ data.geom_xmat[geom].reshape(3, 3).T + data.geom_xpos[geom])[:, 2]
    assert quality["feet_penetration_max_mm"] == pytest.approx(-1000.0 * world_z.min(), abs=1e-3)


def test_lifted_clip_neither_penetrates_nor_stands(g1, g1_dance) -> None:
    reference, quality = g1_dance
    lifted = dataclasses.replace(
        reference, root_pos=reference.root_pos + [0.0, 0.0, 1.0], body_pos_w=reference.body_pos_w + [0.0, 0.0, 1.0]
    )
    lifted_quality = retarget_quality(g1, lifted)
    assert lifted_quality["penetration_max_mm"] == 0.0
    assert lifted_quality["penetration_p95_mm"] == 0.0
    # No foot ever within the contact height: skating is averaged over no frames and reported as 0.0.
    assert lifted_quality["skate_stance_mean_mm_s"] == 0.0
    for key in ("joint_limit_violations", "velocity_limit_violations", "self_collision_frames", "jerk_mean"):
        assert lifted_quality[key] == quality[key]


def test_joint_beyond_its_limit_counts_frames(g1) -> None:
    joint_pos = _standing(g1, 40)
    elbow = g1.config.joint_names.index("left_elbow_joint")
    joint_pos[10:17, elbow] = g1.joint_range[elbow, 1] + 0.1
    assert retarget_quality(g1, _hand_built(g1, joint_pos))["joint_limit_violations"] == 7
    assert retarget_quality(g1, _hand_built(g1, _standing(g1, 40)))["joint_limit_violations"] == 0


@pytest.mark.parametrize(("speed_factor", "expected"), [(1.5, 9), (0.95, 0)])
def test_velocity_ramp_counts_frames_above_the_limit(g1, speed_factor: float, expected: int) -> None:
    fps, start, end = 1000.0, 100, 110
    knee = g1.config.joint_names.index("left_knee_joint")
    speed = speed_factor * g1.config.velocity_limit[knee]
    joint_pos = _standing(g1, 300)
    # A linear ramp over frames 100..110: central differences see the full speed strictly inside,
    # half of it on the two corner frames.
    joint_pos[:, knee] += speed / fps * np.clip(np.arange(300) - start, 0, end - start)
    quality = retarget_quality(g1, _hand_built(g1, joint_pos, fps))
    assert quality["velocity_limit_violations"] == expected
    assert quality["joint_limit_violations"] == 0


def test_jerk_of_a_cubic(g1) -> None:
    a = 0.5
    fps = 50.0
    t = np.arange(50) / fps
    joint_pos = _standing(g1, 50) + a * t[:, None] ** 3
    # The third difference of a cubic is exact, so every frame (ends included) sees d3q/dt3 = 6a.
    jerk = retarget_quality(g1, _hand_built(g1, joint_pos, fps))["jerk_mean"]
    assert jerk == pytest.approx(6.0 * a, rel=1e-6)


def test_elbow_in_torso_counts_as_self_collision(g1) -> None:
    pose = g1.config.default_pos.copy()
    for joint, value in ELBOW_IN_TORSO.items():
        pose[g1.config.joint_names.index(joint)] = value
    joint_pos = _standing(g1, 30)
    joint_pos[5:11] = pose
    reference = _hand_built(g1, joint_pos)

    # Hand check with MuJoCo: the elbow is well inside the torso, far beyond the 5 mm threshold.
    model = g1.model
    data = mujoco.MjData(model)
    data.qpos[:3], data.qpos[3:7] = reference.root_pos[5], reference.root_quat[5]
    data.qpos[g1.qpos_indices] = pose
    mujoco.mj_kinematics(model, data)
    elbow, torso = (
        [g for g in range(model.ngeom) if model.geom_bodyid[g] == g1.body_ids[b] and model.geom_contype[g]]
        for b in ("left_elbow_link", "torso_link")
    )
    depth = min(mujoco.mj_geomDistance(model, data, e, t, 1.0, None) for e in elbow for t in torso)
    assert depth < -0.02

    assert retarget_quality(g1, reference)["self_collision_frames"] == 6
    assert retarget_quality(g1, _hand_built(g1, _standing(g1, 30)))["self_collision_frames"] == 0
    # A deeper threshold than the penetration forgives it.
    deep = QualityThresholds(self_collision_depth_m=-depth + 0.01)
    assert retarget_quality(g1, reference, deep)["self_collision_frames"] == 0


def test_keypoint_error(g1) -> None:
    reference = _hand_built(g1, _standing(g1, 20))
    bodies = ["left_elbow_link", "right_ankle_roll_link", "pelvis"]
    exact = reference.body_pos_w[:, [reference.body_names.index(b) for b in bodies]]
    assert (
        retarget_quality(g1, reference, keypoint_targets=exact, keypoint_bodies=bodies)["keypoint_error_mean_mm"] == 0.0
    )
    shifted = exact + [0.018, 0.0, -0.024]  # 3 cm
    quality = retarget_quality(g1, reference, keypoint_targets=shifted, keypoint_bodies=bodies, frames_per_s=123.4)
    assert quality["keypoint_error_mean_mm"] == pytest.approx(30.0, abs=1e-3)
    assert quality["fps_frames_per_s"] == 123.4
    n = reference.n_frames
    wrong_shape = rf"^keypoint_targets has shape \({n}, 2, 3\), expected \({n}, {len(bodies)}, 3\)$"
    with pytest.raises(PipelineError, match=wrong_shape):
        retarget_quality(g1, reference, keypoint_targets=exact[:, :2], keypoint_bodies=bodies)
    with pytest.raises(PipelineError, match=r"^keypoint body 'nose' is not among the reference's bodies$"):
        retarget_quality(g1, reference, keypoint_targets=exact, keypoint_bodies=["left_elbow_link", "nose", "pelvis"])


def _exact_lowest_z(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> float:
    """Lowest world z of one posed geom, from its full mesh or its analytic shape."""
    rotation = data.geom_xmat[geom].reshape(3, 3)
    centre = data.geom_xpos[geom]
    size = model.geom_size[geom]
    kind = model.geom_type[geom]
    if kind == mujoco.mjtGeom.mjGEOM_MESH:
        mesh = model.geom_dataid[geom]
        vertices = model.mesh_vert[model.mesh_vertadr[mesh] : model.mesh_vertadr[mesh] + model.mesh_vertnum[mesh]]
        return float((vertices @ rotation.T + centre)[:, 2].min())
    axis_z = rotation[2, 2]
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return float(centre[2] - size[0])
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return float(centre[2] - size[1] * abs(axis_z) - size[0])
    assert kind == mujoco.mjtGeom.mjGEOM_CYLINDER
    return float(centre[2] - size[1] * abs(axis_z) - size[0] * np.sqrt(max(0.0, 1.0 - axis_z**2)))


@pytest.mark.parametrize("name", available_robots())
def test_body_hulls_match_posed_geometry(name: str) -> None:
    """Support points give each body's lowest collision point within 1 mm, on random tumbling poses
    (cylinders are sampled on their rims; meshes and spheres are exact)."""
    robot = load_robot(name)
    model, data = robot.model, mujoco.MjData(robot.model)
    hulls = BodyHulls.from_robot(robot)
    rng = np.random.default_rng(0)
    for _ in range(5):
        quat = rng.normal(size=4)
        data.qpos[:3] = [0.0, 0.0, 1.0]
        data.qpos[3:7] = quat / np.linalg.norm(quat)
        low, high = robot.joint_range.T
        data.qpos[robot.qpos_indices] = rng.uniform(low, high)
        mujoco.mj_kinematics(model, data)
        names = [model.body(b).name for b in range(1, model.nbody)]
        ours = hulls.lowest_z(data.xpos[None, 1:], data.xquat[None, 1:], names)
        for k, body in enumerate(hulls.body_ids):
            geoms = set(collision_geoms(model, int(body)))
            if model.body(int(body)).name in robot.config.foot_bodies:  # and the foot meshes a viewer sees
                geoms |= {g for g in range(model.ngeom) if model.geom_bodyid[g] == body and model.geom_dataid[g] >= 0}
            exact = min(_exact_lowest_z(model, data, g) for g in geoms)
            assert ours[0, k] == pytest.approx(exact, abs=1e-3)


@pytest.mark.parametrize("name", ["g1", "h1"])
def test_floor_limit_scans_every_body_that_can_reach_the_floor(name: str) -> None:
    """On random poses from lying to standing: no body's lowest point is below its `lowest_bound`,
    the bound skips bodies, and the floor limit's lowest points are a full scan's wherever a body
    can come within the asked distance of the floor (the others cannot)."""
    robot = load_robot(name)
    model = robot.model
    data = mujoco.MjData(model)
    hulls = BodyHulls.from_robot(robot)
    floor = FloorLimit(model, hulls, clearance_m=0.005, detection_m=0.05)
    within = 0.06
    rng = np.random.default_rng(1)
    names = [model.body(b).name for b in range(1, model.nbody)]
    skipped = 0
    for height in np.linspace(0.1, 1.1, 12):
        quat = rng.normal(size=4)
        data.qpos[:3] = [0.0, 0.0, height]
        data.qpos[3:7] = quat / np.linalg.norm(quat)
        low, high = robot.joint_range.T
        data.qpos[robot.qpos_indices] = rng.uniform(low, high)
        mujoco.mj_kinematics(model, data)
        full = hulls.lowest_z(data.xpos[None, 1:], data.xquat[None, 1:], names)[0]
        bound = hulls.lowest_bound(data.xpos[hulls.body_ids, 2], data.xmat[hulls.body_ids, 6:9])
        assert np.all(bound <= full + 1e-9)
        lowest, index = floor.lowest_points(data, within)
        scanned = index >= 0
        np.testing.assert_allclose(lowest[scanned], full[scanned], rtol=0, atol=1e-12)
        assert np.all(full[~scanned] >= within)
        skipped += int((~scanned).sum())
    assert skipped > 0


def test_support_candidates_find_the_full_scans_lowest_point_while_the_body_turns(g1) -> None:
    """G1's pelvis hull (thousands of points) turned in small random steps, 400 times: the cached
    candidates give the full scan's index and height every time, search a small part of the hull
    between scans, and scan again only after the turn passes `reuse`."""
    hulls = BodyHulls.from_robot(g1)
    k = hulls.body_names.index(g1.config.root_body)
    points = hulls.points[k]
    radii = hulls.radii[k]
    reuse = 0.05
    candidates = SupportCandidates(points, radii, reuse)
    rng = np.random.default_rng(3)
    up = np.array([0.0, 0.0, 1.0])
    searched = []
    for _ in range(400):
        up = up + rng.normal(scale=0.01, size=3)
        up /= np.linalg.norm(up)
        index, z = candidates.lowest(0.7, up)
        full = 0.7 + points @ up - radii
        assert index == int(np.argmin(full))
        assert z == full.min()
        assert np.linalg.norm(up - candidates.scanned_along) <= reuse
        searched.append(len(candidates.subset))
    assert len(points) > 1000
    assert np.median(searched) < 0.1 * len(points)


def test_knees_through_the_floor_are_seen_with_feet_clear(g1) -> None:
    """Shins folded back (feet up behind), the body lowered until the feet just clear the floor: the
    feet-only ruler reads 0, the whole-body one reads the knees' depth."""
    n_frames = 20
    joint_pos = _standing(g1, n_frames)
    names = list(g1.config.joint_names)
    for side in ("left", "right"):
        joint_pos[:, names.index(f"{side}_hip_pitch_joint")] = 0.0
        joint_pos[:, names.index(f"{side}_knee_joint")] = 2.6
        joint_pos[:, names.index(f"{side}_ankle_pitch_joint")] = 0.0
    root_quat = np.tile([1.0, 0.0, 0.0, 0.0], (n_frames, 1))
    contact = np.zeros((n_frames, 2), bool)
    at_zero = reference_from_joint_trajectory(g1, 50.0, np.zeros((n_frames, 3)), root_quat, joint_pos, contact)
    feet = FootMeshes.from_robot(g1).lowest_z(at_zero.body_pos_w, at_zero.body_quat_w, at_zero.body_names)
    root_pos = np.tile([0.0, 0.0, 0.005 - feet.min()], (n_frames, 1))
    reference = reference_from_joint_trajectory(g1, 50.0, root_pos, root_quat, joint_pos, contact)
    hulls = BodyHulls.from_robot(g1)
    lowest = hulls.lowest_z(reference.body_pos_w, reference.body_quat_w, reference.body_names)
    quality = retarget_quality(g1, reference)
    assert quality["feet_penetration_max_mm"] == 0.0
    assert quality["penetration_max_mm"] > 100.0
    assert quality["penetration_max_mm"] == pytest.approx(-1000.0 * lowest.min(), abs=1e-3)
    sink = hulls.sink_depth(reference.body_pos_w, reference.body_quat_w, reference.body_names)
    np.testing.assert_allclose(sink, np.maximum(-lowest.min(axis=1), 0.0), rtol=0, atol=1e-12)
    # Every other frame two metres up: only the frames left on the floor sink.
    lift = np.zeros_like(reference.body_pos_w)
    lift[::2, :, 2] = 2.0
    mixed = hulls.sink_depth(reference.body_pos_w + lift, reference.body_quat_w, reference.body_names)
    assert not mixed[::2].any()
    np.testing.assert_allclose(mixed[1::2], sink[1::2], rtol=0, atol=1e-12)
    legs = {f"{side}_{link}" for side in ("left", "right") for link in ("hip_yaw_link", "knee_link")}
    assert quality["penetration_deepest_body"] in legs
    series = quality_series(g1, reference)
    assert series["penetration_m"].shape == (n_frames,)
    # The deepest body is the argmax over every body's lowest point, though only bodies whose
    # bound reaches below the floor are looked at.
    np.testing.assert_array_equal(series["penetration_body"], lowest.argmin(axis=1))


def test_pelvis_height_and_divergence_rulers(g1) -> None:
    """A robot that stays standing while the human lies down is caught; so is a frame far off its targets."""
    n_frames = 200
    reference = _hand_built(g1, _standing(g1, n_frames))
    pelvis = reference.body_names.index("pelvis")
    human = reference.body_pos_w[:, pelvis].copy()
    assert retarget_quality(g1, reference, human_pelvis=human)["pelvis_height_dev_p95_m"] == 0.0
    human[150:, 2] -= 0.6  # the human lies down for the last quarter; the robot does not follow
    quality = retarget_quality(g1, reference, human_pelvis=human)
    assert quality["pelvis_height_dev_p95_m"] == pytest.approx(0.6, abs=1e-6)
    bodies = ["pelvis", "torso_link"]
    targets = reference.body_pos_w[:, [reference.body_names.index(b) for b in bodies]].copy()
    targets += 0.01  # a small, even error everywhere ...
    targets[100:103] += 0.5  # ... and three frames far off
    quality = retarget_quality(g1, reference, keypoint_targets=targets, keypoint_bodies=bodies)
    assert quality["diverged_frames"] == 3
    assert quality["keypoint_error_max_mm"] == pytest.approx(1000.0 * np.sqrt(3 * 0.51**2), abs=1e-3)
    assert quality["root_speed_p999_m_s"] == 0.0
    # A take off its targets from the middle to the end (a leg folded onto its alias), by less than
    # the absolute limit: it raises the take's median, not its lower quartile.
    folded = targets.copy()
    folded[100:103] -= 0.5  # only the even error
    folded[80:] += 0.15
    quality = retarget_quality(g1, reference, keypoint_targets=folded, keypoint_bodies=bodies)
    assert quality["keypoint_error_max_mm"] < 500.0
    assert quality["diverged_frames"] == n_frames - 80
    # A take off its targets through most of its frames (a frozen IK) raises even the quartile; the
    # absolute limit still sees every frame beyond it.
    frozen = targets.copy()
    frozen[40:] += 1.0
    quality = retarget_quality(g1, reference, keypoint_targets=frozen, keypoint_bodies=bodies)
    assert quality["diverged_frames"] == n_frames - 40


def test_range_limited_frames_name_the_joints_held_at_a_bound(g1) -> None:
    joint_pos = _standing(g1, 40)
    assert retarget_quality(g1, _hand_built(g1, joint_pos))["range_limited_frames"] == 0
    names = g1.config.joint_names
    knee = names.index("left_knee_joint")
    roll = names.index("right_ankle_roll_joint")
    joint_pos[5:25, knee] = g1.joint_range[knee, 1]
    joint_pos[20:30, roll] = g1.joint_range[roll, 0] + 0.0005
    joint_pos[30:35, roll] = g1.joint_range[roll, 0] + 0.01  # near, but not held
    quality = retarget_quality(g1, _hand_built(g1, joint_pos))
    assert quality["range_limited_frames"] == 25
    assert quality["range_limited_joints"] == {"left_knee_joint": 20, "right_ankle_roll_joint": 10}
    assert quality["joint_limit_violations"] == 0


def test_planted_foot_turn_counts_planted_feet_only(g1) -> None:
    """A sole turned 12 deg from its target while planted is measured; a foot in the air is not."""
    n_frames = 40
    standing = _hand_built(g1, _standing(g1, n_frames))
    planted = np.zeros((n_frames, 2), dtype=bool)
    planted[:30, 0] = True  # left foot planted for 30 frames, the right never
    reference = dataclasses.replace(standing, foot_contact=planted)
    feet = [reference.body_names.index(foot) for foot in g1.config.foot_bodies]
    exact = Rotation.from_quat(reference.body_quat_w[:, feet].reshape(-1, 4), scalar_first=True)
    exact = exact.as_matrix().reshape(n_frames, 2, 3, 3)
    assert retarget_quality(g1, reference, foot_orientations=exact)["planted_foot_turn_p95_deg"] == 0.0
    turned = exact @ Rotation.from_euler("x", 12.0, degrees=True).as_matrix()
    turned[:, 1] = Rotation.from_euler("y", 80.0, degrees=True).as_matrix()  # never planted: ignored
    series = quality_series(g1, reference, foot_orientations=turned)["planted_foot_turn_deg"]
    assert np.allclose(series[:30], 12.0) and np.isnan(series[30:]).all()
    assert retarget_quality(g1, reference, foot_orientations=turned)["planted_foot_turn_p95_deg"] == 12.0
    assert retarget_quality(g1, reference)["planted_foot_turn_p95_deg"] is None
    with pytest.raises(PipelineError, match="foot_orientations has shape"):
        retarget_quality(g1, reference, foot_orientations=exact[:, :1])


def test_a_geom_the_floor_ruler_cannot_measure_is_named() -> None:
    """An ellipsoid on a robot body is refused in one line that names the geom and the body."""
    robot = load_robot("g1")
    spec = mujoco.MjSpec.from_string(
        '<mujoco><worldbody><body name="torso"><freejoint/><geom name="belly" type="ellipsoid" size="0.1 0.2 0.3"/>'
        "</body></worldbody></mujoco>"
    )
    broken = dataclasses.replace(robot, model=spec.compile(), config=dataclasses.replace(robot.config, foot_bodies=()))
    with pytest.raises(PipelineError) as error:
        BodyHulls.from_robot(broken)
    assert str(error.value) == (
        "robot model: collision geom belly of body 'torso' is a mjGEOM_ELLIPSOID, which the floor ruler cannot measure"
    )


def test_mesh_hulls_are_made_once_per_model_and_shared_read_only(g1) -> None:
    """The IK, the floor ruler and the skate ruler of one retarget share each hull: the second ask
    returns the first's array, equal to a hull made afresh, and nobody can write into it."""
    first = FootMeshes.from_robot(g1).vertices[0]
    again = FootMeshes.from_robot(g1).vertices[0]
    assert again is first
    assert not first.flags.writeable
    model = g1.model
    foot = g1.body_ids[g1.config.foot_bodies[0]]
    meshes = [
        g
        for g in range(model.ngeom)
        if model.geom_bodyid[g] == foot and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
    ]
    fresh = hull_vertices(np.concatenate([mesh_points_in_body(model, g) for g in meshes]))
    np.testing.assert_array_equal(first, fresh)
