"""Retargeting real LAFAN1 clips: the constraints hold, the feet behave, bad input says what is wrong."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from types import SimpleNamespace

import mink
import numpy as np
import pytest
from conftest import LAFAN_DIR, cli
from scipy.spatial.transform import Rotation

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.contact import contact_runs
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, HumanMotion, human_motion_from_bvh
from rd_pipeline.retarget.collision import colliding_copy, pair_geoms, require_same_pairs
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.quality import retarget_quality
from rd_pipeline.retarget.retarget import RetargetResult, retarget
from rd_pipeline.robots import available_robots, load_robot
from rd_pipeline.robots.model import collision_geom_pairs

SPEC_QUALITY_KEYS = {
    "fps_frames_per_s",
    "penetration_max_mm",
    "penetration_p95_mm",
    "skate_stance_mean_mm_s",
    "joint_limit_violations",
    "velocity_limit_violations",
    "self_collision_frames",
    "jerk_mean",
    "keypoint_error_mean_mm",
}


def _human(motion: str, seconds: float | None = None) -> HumanMotion:
    human = human_motion_from_bvh(read_bvh(LAFAN_DIR / f"{motion}.bvh"), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
    if seconds is None:
        return human
    n = int(seconds * human.fps)
    return dataclasses.replace(human, pos_w=human.pos_w[:n], quat_w=human.quat_w[:n])


def _retarget(robot: str, human: HumanMotion) -> RetargetResult:
    return retarget(human, load_robot(robot), RetargetConfig())


@pytest.fixture(scope="module")
def g1_dance() -> RetargetResult:
    return _retarget("g1", _human("dance1_subject2", seconds=25.0))


@pytest.mark.slow
def test_constraints_hold_on_a_real_clip(g1_dance: RetargetResult) -> None:
    robot = load_robot("g1")
    q = retarget_quality(
        robot,
        g1_dance.reference,
        keypoint_targets=g1_dance.targets.positions,
        keypoint_bodies=g1_dance.targets.bodies,
        foot_orientations=g1_dance.targets.foot_orientations(robot.config.foot_bodies),
    )
    assert g1_dance.reference.fps == 50.0 and g1_dance.reference.n_frames == 1250
    assert q["penetration_max_mm"] <= 5.0
    assert q["joint_limit_violations"] == 0
    assert q["velocity_limit_violations"] == 0
    assert q["self_collision_frames"] == 0
    assert q["skate_stance_mean_mm_s"] <= 20.0
    assert q["keypoint_error_mean_mm"] < 100.0
    # Planted soles turn off their targets by a few degrees (8.4 at p95 here; 4.0 with the foot
    # orientation cost at 10): the ruler sees it, and it stays bounded.
    assert 5.0 < q["planted_foot_turn_p95_deg"] < 14.0


@pytest.mark.slow
def test_planted_feet_stay_put_and_follow_their_sole_target(g1_dance: RetargetResult) -> None:
    reference = g1_dance.reference
    robot = load_robot("g1")
    assert 0.3 < reference.foot_contact.mean() < 0.95
    angles, flat, slides = [], [], []
    for side, foot in enumerate(robot.config.foot_bodies):
        b = reference.body_names.index(foot)
        for start, end in contact_runs(reference.foot_contact[:, side]):
            if end - start < 10:
                continue
            # Away from the ends of a plant (where the smoothing eases in), the foot does not move.
            inner = slice(start + 3, end - 3)
            slides.append(np.ptp(reference.body_pos_w[inner, b, :2], axis=0).max())
            up = Rotation.from_quat(reference.body_quat_w[inner, b][:, [1, 2, 3, 0]]).apply([0, 0, 1])
            target_up = g1_dance.targets.orientations[foot][inner][:, :, 2]
            angles.append(np.degrees(np.arccos(np.clip(np.einsum("ti,ti->t", up, target_up), -1, 1))))
            flat.append(np.degrees(np.arccos(np.clip(target_up[:, 2], -1, 1))) < 1.0)
    # Flat, or tilted as the human's foot is (heel up): the sole follows its target; a heel-up
    # target beyond the ankle's range is followed as far as the range allows. The foot orientation
    # cost trades sole tilt for stillness: at 5 (the default) this excerpt measures tilt p95 5.3 deg,
    # max 18.2, and plants slide at most 3.9 mm; at 10, tilt p95 3.2, max 13.6, slides up to 8.3 mm.
    # The plant lock, which holds the foot's position with the leg's joints alone, trades tilt too:
    # p95 5.1 -> 6.2 deg, max 17.2 -> 18.0, median slide 0.56 -> 0.06 mm, largest 3.4 -> 2.5 mm.
    angles = np.concatenate(angles)
    assert np.percentile(angles, 95) < 7.0 and angles.max() < 20.0
    assert np.concatenate(flat).mean() > 0.5
    slides = np.array(slides)
    assert np.median(slides) < 0.0002 and slides.max() < 0.005


def test_scale_comes_from_the_models() -> None:
    human = _human("dance1_subject1", seconds=4.0)
    scales = {name: _retarget(name, human).targets.human_scale for name in ("g1", "h1_2")}
    # Leg-length ratios: the G1 is a child-sized robot, the H1-2 close to an adult.
    assert 0.6 < scales["g1"] < 0.8 < scales["h1_2"] < 1.05


def test_h1_2_wrists_and_limits() -> None:
    result = _retarget("h1_2", _human("dance1_subject3", seconds=8.0))
    robot = load_robot("h1_2")
    q = retarget_quality(robot, result.reference)
    assert q["joint_limit_violations"] == 0 and q["velocity_limit_violations"] == 0
    assert q["penetration_max_mm"] <= 5.0
    assert result.reference.joint_pos.shape == (400, 27)


def test_nan_frames_are_rejected() -> None:
    human = _human("dance1_subject2", seconds=2.0)
    pos = human.pos_w.copy()
    pos[17, 3, 1] = np.nan
    with pytest.raises(PipelineError, match=r"^human motion has a non-finite position at frame 17$"):
        _retarget("g1", dataclasses.replace(human, pos_w=pos))


def test_clip_shorter_than_a_frame_period() -> None:
    human = _human("dance1_subject2", seconds=2.0)
    one = dataclasses.replace(human, fps=100.0, pos_w=human.pos_w[:1], quat_w=human.quat_w[:1])
    with pytest.raises(PipelineError, match=r"shorter than one frame period"):
        _retarget("g1", one)


def test_retarget_map_with_an_unknown_human_joint() -> None:
    robot = load_robot("g1")
    config = dataclasses.replace(
        robot.config, retarget_map={**robot.config.retarget_map, "left_elbow_link": "LeftElbow"}
    )
    broken = dataclasses.replace(robot, config=config)
    with pytest.raises(PipelineError, match=r"bodies.retarget names human joint 'LeftElbow', not in the skeleton"):
        retarget(_human("dance1_subject2", seconds=1.0), broken, RetargetConfig())


@pytest.mark.slow
def test_stage_writes_reference_and_quality(artifacts: Path) -> None:
    result = cli("run", "--robot", "g1", "--motion", "dance1_subject3", "--until", "retarget")
    assert result.returncode == 0, result.stderr
    (folder,) = (artifacts / "retarget" / "g1" / "dance1_subject3").iterdir()
    quality = json.loads((folder / "quality.json").read_text())
    assert SPEC_QUALITY_KEYS <= set(quality)
    assert quality["joint_limit_violations"] == 0 and quality["penetration_max_mm"] <= 5.0
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["upstream"] == {
        "parse": json.loads(
            next((artifacts / "parse" / "dance1_subject3").iterdir()).joinpath("manifest.json").read_text()
        )["key"]
    }
    assert manifest["metrics"]["skate_stance_mean_mm_s"] == quality["skate_stance_mean_mm_s"]


def test_lagging_windows_are_padded_merged_and_off_at_zero_ratio() -> None:
    from rd_pipeline.retarget.config import LagRepair
    from rd_pipeline.retarget.repair import RepairWindow, lagging_windows

    errors = np.full(200, 0.05)
    errors[[40, 41, 60, 150]] = 0.30  # 0.30 > max(2 x 0.05, 0.05 + 0.1)
    errors[100] = 0.14  # under the margin: not lagging
    repair = LagRepair(error_ratio=2.0, error_margin_m=0.1, padding_s=0.2, rejoin_s=0.1)
    assert lagging_windows(errors, 50.0, repair) == [RepairWindow(30, 70, 75), RepairWindow(140, 160, 165)]
    errors[199] = 0.30
    assert lagging_windows(errors, 50.0, repair)[-1] == RepairWindow(189, 199, 199)
    assert lagging_windows(errors, 50.0, dataclasses.replace(repair, error_ratio=0.0)) == []


def _g1_dance_ik(seconds: float):
    """The retarget's IK, with default params, for G1 on the first `seconds` of dance1_subject2."""
    from rd_pipeline.retarget.ik import RetargetIk
    from rd_pipeline.retarget.quality import FootMeshes
    from rd_pipeline.retarget.targets import build_targets
    from rd_pipeline.robots.hulls import BodyHulls

    robot = load_robot("g1")
    params = RetargetConfig()
    feet = FootMeshes.from_robot(robot)
    human = _human("dance1_subject2", seconds=seconds)
    targets = build_targets(human, robot, params.fps, feet.vertices, params.contact, params.shape, params.body_contact)
    return RetargetIk(robot, targets, params.weights, params.ik, BodyHulls.from_robot(robot))


def test_frames_visited_backward_get_their_own_task_costs() -> None:
    # The lag repair solves stretches backward: each frame must hold its own costs (planted or
    # swinging feet), not those of the frame visited before it.
    ik = _g1_dance_ik(seconds=8.0)
    targets = ik.targets
    changes = np.flatnonzero(np.any(ik.position_costs[1:] != ik.position_costs[:-1], axis=(1, 2)))
    assert len(changes) >= 2, "the excerpt should switch feet between planted and swinging"
    q = ik.initial_configuration(ik.start_postures[0])
    for t in reversed(range(targets.n_frames)):
        q = ik.solve_frame(t, q, ik.root_steps[t], np.inf)
        held = ik.key_bodies.body_costs[:, :3]
        np.testing.assert_array_equal(held, ik.position_costs[t])


def test_the_key_bodies_task_builds_the_qp_of_one_mink_frame_task_per_body() -> None:
    """KeyBodiesTask stacks FrameTask's error and Jacobian per body: on 4 s of G1 dance the QP's
    objective is the one a list of mink.FrameTask builds, bit for bit, while planted and swinging
    feet change the costs (and a frame task's cost moved by one part in 10^6 changes it)."""
    ik = _g1_dance_ik(seconds=4.0)
    qpos = ik.solve(range(ik.targets.n_frames))
    key_bodies = ik.key_bodies
    frame_tasks = [
        mink.FrameTask(body, "body", 1.0, float(key_bodies.body_costs[k, 3]), lm_damping=ik.settings.lm_damping)
        for k, body in enumerate(ik.targets.bodies)
    ]
    for t in range(1, ik.targets.n_frames, 5):
        ik._set_frame_targets(t)
        for k, task in enumerate(frame_tasks):
            task.set_position_cost(ik.position_costs[t, k])
            task.set_target(mink.SE3(wxyz_xyz=ik.target_poses[t, k]))
        ik.configuration.update(qpos[t - 1])
        ours = mink.build_ik(ik.configuration, ik.tasks, 1.0, damping=ik.damping)
        theirs = mink.build_ik(ik.configuration, [*frame_tasks, ik.posture], 1.0, damping=ik.damping)
        np.testing.assert_array_equal(ours.P, theirs.P)
        np.testing.assert_array_equal(ours.q, theirs.q)
    frame_tasks[0].set_position_cost(ik.position_costs[t, 0] * (1 + 1e-6))
    moved = mink.build_ik(ik.configuration, [*frame_tasks, ik.posture], 1.0, damping=ik.damping)
    assert not np.array_equal(ours.P, moved.P)


def test_the_ik_step_is_mink_solve_ik_s_though_it_drops_the_rows_out_of_reach() -> None:
    """The QP leaves out mink's collision rows with an infinite bound (pairs out of reach) and
    mink's range check: on 4 s of G1 dance, each frame's first step (from the previous frame's
    pose) is mink.solve_ik's, bit for bit, where rows were dropped and the planted feet's floor
    rows hold the step (leaving those out changes every component)."""
    ik = _g1_dance_ik(seconds=4.0)
    qpos = ik.solve(range(ik.targets.n_frames))
    dropped = 0
    holding = 0
    for t in range(1, ik.targets.n_frames, 5):
        ik._set_frame_targets(t)
        ik.step_limit.start_frame(qpos[t - 1], ik.root_steps[t])
        ik.configuration.update(qpos[t - 1])
        ours = ik._solve_qp(ik.tasks)
        theirs = mink.solve_ik(
            ik.configuration, ik.tasks, 1.0, ik.settings.solver, damping=ik.damping, limits=ik.limits
        )
        np.testing.assert_array_equal(ours, theirs)
        built = mink.build_ik(ik.configuration, ik.tasks, 1.0, damping=ik.damping, limits=ik.limits)
        dropped += int(np.isinf(built.h).sum())
        holding += int(np.sum(np.isclose(built.G @ theirs, built.h, rtol=0.0, atol=1e-9)))
    assert dropped > 0
    assert holding > 0


@pytest.mark.parametrize("name", available_robots())
def test_the_ik_avoids_every_pair_its_step_check_counts(name: str) -> None:
    """mink drops pairs whose geoms fail MuJoCo's contype/conaffinity test; H1-2's wrists are visual
    geoms only. Without the marked copy its QP avoided 6 of 10 pairs, steered a wrist into the torso
    on ground2_subject3 at 55 s, and the step check then refused every step for two minutes."""
    robot = load_robot(name)
    model = robot.model
    pairs = pair_geoms(robot)
    checked = {tuple(sorted(pair)) for pair in collision_geom_pairs(robot).tolist()}
    marked = mink.CollisionAvoidanceLimit(colliding_copy(model, pairs), pairs)
    assert {tuple(sorted(pair)) for pair in marked.geom_id_pairs} == checked
    require_same_pairs(robot, marked)  # what RetargetIk checks when it is built
    plain = {tuple(sorted(pair)) for pair in mink.CollisionAvoidanceLimit(model, pairs).geom_id_pairs}
    assert (plain == checked) == (name != "h1_2")


class _LaggingIk:
    """What `repair_lag` reads of a RetargetIk: a real robot, and keypoint errors scripted to lag
    in frames 40-59 of the first solve and to be lower wherever a re-solve is asked about."""

    def __init__(self, robot) -> None:
        self.robot = robot
        self.settings = RetargetConfig().ik
        self.targets = SimpleNamespace(fps=50.0)

    def keypoint_errors(self, qpos: np.ndarray, first: int = 0) -> np.ndarray:
        if first == 0:
            errors = np.full(len(qpos), 0.05)
            errors[40:60] = 0.4
            return errors
        return np.full(len(qpos), 0.04)


def _pose_in_contact(
    robot, standing: np.ndarray, deeper_than: float = 0.0, shallower_than: float = np.inf
) -> np.ndarray:
    """`standing` with its joints drawn at random (fixed seed) until the deepest configured pair
    interpenetrates by more than `deeper_than` and less than `shallower_than` (m)."""
    from rd_pipeline.retarget.quality import colliding_frames

    rng = np.random.default_rng(0)
    for _ in range(200):
        poses = np.repeat(standing[None], 64, axis=0)
        poses[:, robot.qpos_indices] = rng.uniform(*robot.joint_range.T, size=(64, len(robot.qpos_indices)))
        touching = colliding_frames(robot, poses, deeper_than)
        if np.isfinite(shallower_than):
            touching &= ~colliding_frames(robot, poses, shallower_than)
        if touching.any():
            return poses[np.flatnonzero(touching)[0]]
    raise AssertionError(f"no random pose brought a configured pair {deeper_than}-{shallower_than} m deep")


def _g1_standing(robot) -> np.ndarray:
    standing = np.zeros(robot.model.nq)
    standing[2] = 0.8
    standing[3] = 1.0
    standing[robot.qpos_indices] = robot.config.default_pos
    return standing


def _repair_with(monkeypatch, robot, qpos: np.ndarray, offset: float, pose: np.ndarray | None):
    """`repair_lag` over `qpos` (lagging in frames 40-59, `_LaggingIk`) when the re-solve moves every
    joint by `offset` and, if `pose` is given, puts it in the window's middle frame."""
    from rd_pipeline.retarget import repair as repair_module
    from rd_pipeline.retarget.config import LagRepair

    def forward_frames(ik, qpos, errors, window, lag_limit, repair) -> np.ndarray:
        return qpos[window.anchor + 1 : window.rejoin_end + 1].copy()

    def solve_again(ik, qpos, guide, window, lag_limit, repair) -> tuple[np.ndarray, np.ndarray]:
        candidate = guide.copy()
        candidate[:, robot.qpos_indices] += offset
        if pose is not None:
            candidate[len(candidate) // 2] = pose
        return candidate, ik.keypoint_errors(candidate, window.anchor + 1)

    monkeypatch.setattr(repair_module, "_guide", forward_frames)
    monkeypatch.setattr(repair_module, "_best_re_solve", solve_again)
    return repair_module.repair_lag(_LaggingIk(robot), qpos, LagRepair())


def test_the_lag_repair_keeps_no_resolve_that_brings_a_pair_into_contact(monkeypatch) -> None:
    # A re-solve that lags less is kept, unless it puts a configured body pair into contact that the
    # first solve kept apart (its fade back into the first solve blends two configurations).
    from rd_pipeline.retarget.quality import colliding_frames

    robot = load_robot("g1")
    standing = _g1_standing(robot)
    qpos = np.repeat(standing[None], 100, axis=0)
    assert not colliding_frames(robot, qpos, 0.0).any()
    contact = _pose_in_contact(robot, standing)
    # A re-solve that differs, within the ranges.
    out, repaired = _repair_with(monkeypatch, robot, qpos, 0.01, None)
    assert repaired == 1
    assert not np.array_equal(out, qpos)
    out, repaired = _repair_with(monkeypatch, robot, qpos, 0.01, contact)
    assert repaired == 0
    assert np.array_equal(out, qpos)


def test_the_lag_repair_keeps_no_resolve_that_presses_a_touching_pair_deeper(monkeypatch) -> None:
    # Where the first solve already touches (within the step check's depth limit), a re-solve may
    # touch as much, but not press the pair deeper than that limit (H1-2 ground2_subject3: a wrist
    # 2 mm into the torso, 12 mm after a re-solve that was kept).
    robot = load_robot("g1")
    limit = RetargetConfig().ik.pair_depth_limit_m
    standing = _g1_standing(robot)
    shallow = _pose_in_contact(robot, standing, 0.0, limit)
    deep = _pose_in_contact(robot, standing, limit + 0.005)
    qpos = np.repeat(shallow[None], 100, axis=0)
    assert _repair_with(monkeypatch, robot, qpos, 0.0, None)[1] == 1
    assert _repair_with(monkeypatch, robot, qpos, 0.0, deep)[1] == 0


def test_a_catch_up_that_stops_gaining_ends_early(monkeypatch) -> None:
    # The lag repair's re-solves pass a minimum gain: a frame whose catch-up no longer brings it
    # closer stops there instead of running every catch-up iteration.
    from rd_pipeline.retarget.ik import RetargetIk

    params = RetargetConfig()
    ik = _g1_dance_ik(seconds=2.0)
    # solve() fills only the rows it visits: frame 39 is the warm start for frame 40.
    start = ik.solve(range(40))[39]
    iterations = 0
    solve_once = RetargetIk._iterate

    def counted(self, tasks) -> None:
        nonlocal iterations
        iterations += 1
        solve_once(self, tasks)

    monkeypatch.setattr(RetargetIk, "_iterate", counted)
    counts = {}
    errors = {}
    for gain in (-np.inf, params.repair.catch_up_min_gain_m):
        iterations = 0
        ik.configuration.update(start)
        # A lag limit of 0 makes every frame lag: all catch-up iterations run unless stopped.
        ik.solve_frame(40, start, ik.root_steps[40], 0.0, (), gain)
        counts[gain] = iterations
        errors[gain] = ik._keypoint_error(40)
    full, stopped = counts.values()
    assert full == params.ik.iterations + params.ik.catch_up_iterations
    assert params.ik.iterations < stopped < full
    assert abs(errors[params.repair.catch_up_min_gain_m] - errors[-np.inf]) < 0.002


@pytest.mark.slow
def test_a_fast_fall_does_not_fold_a_leg_onto_its_alias() -> None:
    # H1-2's model lets a hip pitch 2.5 rad back. Played 1.3x fast, the push and fall lagged, the
    # IK swung the right leg back to that bound and then rolled it half a turn: the knee where the
    # human's is, bent the wrong way, for the rest of the take. The config's retarget range keeps
    # the hip where performers' hips go; with the model's range the same excerpt folds. It folded
    # at a swinging-foot cost of 20; at today's 50 the leg stays out of reach of the alias here,
    # so the test keeps 20 to hold the range to a real fold; and it holds every body touching the
    # floor however far it slides, as the retargeter then did (letting a sliding body go keeps
    # this excerpt from lagging into the fold at all).
    params = RetargetConfig()
    params = dataclasses.replace(
        params,
        weights=dataclasses.replace(params.weights, swing_feet_position=20.0),
        body_contact=dataclasses.replace(params.body_contact, hold_drift_m=np.inf),
    )
    human = _human("pushAndFall1_subject1")
    first = int(50 * human.fps)
    last = int(66 * human.fps)
    fast = dataclasses.replace(
        human, pos_w=human.pos_w[first:last], quat_w=human.quat_w[first:last], fps=human.fps * 1.3
    )
    robot = load_robot("h1_2")
    unbounded = np.tile([-np.inf, np.inf], (len(robot.config.joint_names), 1))
    model_range = dataclasses.replace(robot, config=dataclasses.replace(robot.config, retarget_range=unbounded))
    hip = robot.config.joint_names.index("right_hip_pitch_joint")
    outcome = {}
    for name, candidate in (("config", robot), ("model", model_range)):
        result = retarget(fast, candidate, params)
        reference = result.reference
        bodies = [reference.body_names.index(b) for b in result.targets.bodies]
        error = np.linalg.norm(reference.body_pos_w[:, bodies] - result.targets.positions, axis=2).mean(axis=1)
        last_seconds = int(3 * result.targets.fps)
        outcome[name] = (reference.joint_pos[:, hip].max(), error[-last_seconds:].mean())
    assert outcome["config"][0] <= robot.retarget_range[hip, 1] + 1e-9
    assert outcome["config"][1] < 0.10
    assert outcome["model"][0] > 2.0
    assert outcome["model"][1] > 0.20


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ("no knee", "bodies.retarget must map a body to LAFAN1 joint 'LeftLeg'"),
        (
            "feet swapped",
            "bodies.retarget maps 'left_ankle_roll_link' to 'LeftFoot', but bodies.feet names 'right_ankle_roll_link'",
        ),
    ],
)
def test_a_retarget_map_the_targets_cannot_use_is_one_line(change: str, message: str) -> None:
    from rd_pipeline.retarget.quality import FootMeshes
    from rd_pipeline.retarget.targets import build_targets

    robot = load_robot("g1")
    config = robot.config
    if change == "no knee":
        config = dataclasses.replace(
            config, retarget_map={b: j for b, j in config.retarget_map.items() if j != "LeftLeg"}
        )
    else:
        config = dataclasses.replace(config, foot_bodies=config.foot_bodies[::-1])
    broken = dataclasses.replace(robot, config=config)
    params = RetargetConfig()
    human = _human("dance1_subject2", seconds=2.0)
    with pytest.raises(PipelineError) as error:
        build_targets(
            human,
            broken,
            params.fps,
            FootMeshes.from_robot(robot).vertices,
            params.contact,
            params.shape,
            params.body_contact,
        )
    assert str(error.value) == f"{config.source}: {message}"
