"""What ends a sim2sim rollout: a reference broken on purpose at a known frame and body must end
the rollout there, named by the failure it broke."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import mujoco
import numpy as np
import pytest
from conftest import RETARGETED_DIR, video_frames

from rd_pipeline.env.config import EnvConfig
from rd_pipeline.errors import PipelineError
from rd_pipeline.evaluation.deploy import reference_baseline_spec
from rd_pipeline.evaluation.disturbances import Disturbances, RandomizedPhysics
from rd_pipeline.evaluation.metrics import per_second, tracked_pct
from rd_pipeline.evaluation.protocol import Protocol, RandomizedProtocol, TrackingTolerance
from rd_pipeline.evaluation.sim2sim import BodySets, Rollout, reference_states, run_rollouts
from rd_pipeline.evaluation.validation import deploy_model
from rd_pipeline.export.exporter import build_policy_spec
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.policy_spec import PolicySpec
from rd_pipeline.robots import load_robot
from rd_pipeline.viz.render import Scene, render_pictures
from rd_pipeline.viz.render_config import RenderConfig

BROKEN_AT = 20
"""The frame from which the broken references leave the robot behind (0.4 s in)."""


class Standing(NamedTuple):
    """A reference and what the zero-action rollouts on it run on."""

    reference: ReferenceMotion
    spec: PolicySpec
    model: mujoco.MjModel
    bodies: BodySets


@pytest.fixture(scope="module")
def standing() -> Standing:
    """G1 dance1_subject2's first 4 s (dataset CSV, standing prelude): the reference fed to PD (zero
    action) stays within the limits well past `BROKEN_AT`, until its left hand lags."""
    robot = load_robot("g1")
    path = RETARGETED_DIR / "g1" / "dance1_subject2.csv"
    reference = import_retargeted_csv(path, robot, 30.0, 50.0, "cubic", ContactThresholds()).reference.frames(0, 200)
    policy_joints = len(robot.config.policy_joints)
    spec = reference_baseline_spec(
        build_policy_spec(robot, EnvConfig(), policy_joints, "import", "k", (0, reference.n_frames))
    )
    rc = robot.config
    bodies = BodySets(rc.root_body, rc.tracking_bodies, rc.termination_bodies, rc.foot_bodies)
    return Standing(reference, spec, deploy_model(spec, Protocol().physics_hz), bodies)


def _rollout(standing: Standing, reference: ReferenceMotion) -> Rollout:
    joints = len(standing.spec.get("joints.policy"))

    def zero(obs: np.ndarray) -> np.ndarray:
        return np.zeros((len(obs), joints), dtype=np.float32)

    starts = np.array([0])
    (rollout,) = run_rollouts(standing.spec, [standing.model], reference, zero, starts, standing.bodies, Protocol())
    return rollout


def test_the_unbroken_prelude_lasts_past_the_break(standing: Standing) -> None:
    rollout = _rollout(standing, standing.reference)
    assert rollout.ended_by == "far left_wrist_roll_rubber_hand"
    assert BROKEN_AT + 10 < rollout.steps < 60  # 37 steps with MuJoCo 4.0
    assert not rollout.completed


def test_a_hand_the_reference_lifts_away_ends_the_rollout_as_far(standing: Standing) -> None:
    reference = standing.reference
    hand = reference.body_names.index("left_wrist_roll_rubber_hand")
    body_pos = reference.body_pos_w.copy()
    body_pos[BROKEN_AT:, hand, 2] += 1.0
    rollout = _rollout(standing, dataclasses.replace(reference, body_pos_w=body_pos))
    assert rollout.ended_by == "far left_wrist_roll_rubber_hand"
    assert rollout.steps == BROKEN_AT
    assert not rollout.completed


def test_a_reference_that_tips_over_ends_the_rollout_as_tilted(standing: Standing) -> None:
    reference = standing.reference
    pelvis = reference.body_names.index("pelvis")
    body_quat = reference.body_quat_w.copy()
    body_quat[BROKEN_AT:, pelvis] = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # 90 degrees about x
    rollout = _rollout(standing, dataclasses.replace(reference, body_quat_w=body_quat))
    assert rollout.ended_by == "tilted"
    assert rollout.steps == BROKEN_AT


def test_validation_steps_the_paper_s_500_hz_whatever_rate_the_policy_trained_at() -> None:
    robot = load_robot("g1")
    mjlab_rate = EnvConfig(physics_dt=0.005, decimation=4)  # 200 Hz physics, 50 Hz policy
    spec = build_policy_spec(robot, mjlab_rate, len(robot.config.policy_joints), "import", "k", (0, 100))
    assert spec.get("rates.physics_hz") == 200.0
    protocol = Protocol()
    assert deploy_model(spec, protocol.physics_hz).opt.timestep == 0.002
    assert protocol.substeps(spec.get("rates.control_hz")) == 10
    with pytest.raises(PipelineError) as error:
        Protocol(physics_hz=333.0).substeps(50.0)
    assert str(error.value) == (
        "validate.protocol.physics_hz 333 is not a whole multiple of the policy's 50 Hz control rate"
    )


def _zero_grid(standing: Standing, disturbances: Disturbances | None, models: list[mujoco.MjModel]) -> list[Rollout]:
    joints = len(standing.spec.get("joints.policy"))
    starts = np.array([0, 40, 80])
    zero = lambda obs: np.zeros((len(obs), joints), dtype=np.float32)
    bodies = standing.bodies
    return run_rollouts(standing.spec, models, standing.reference, zero, starts, bodies, Protocol(), disturbances)


def _randomized(standing: Standing, protocol: RandomizedProtocol, seed: int) -> list[Rollout]:
    joints = standing.spec.get("joints")
    root = standing.model.body(standing.bodies.root).id
    effort = np.asarray(joints["effort_limit"])
    physics = RandomizedPhysics.draw(standing.model, 3, root, effort, protocol, seed)
    disturbances = Disturbances.start(physics, joints["actuated"], 0.02, protocol, seed)
    return _zero_grid(standing, disturbances, physics.models)


def test_randomized_rollouts_repeat_with_their_seed_and_feel_the_disturbances(standing: Standing) -> None:
    nominal = _zero_grid(standing, None, [standing.model] * 3)
    protocol = RandomizedProtocol(models_per_seed=2)
    first = _randomized(standing, protocol, 10_001)
    again = _randomized(standing, protocol, 10_001)
    other = _randomized(standing, protocol, 10_002)
    errors = lambda rollouts: np.concatenate([r.errors["E_mpjpe"] for r in rollouts])
    assert np.array_equal(errors(first), errors(again))
    assert not np.array_equal(errors(first), errors(other))
    assert not np.array_equal(errors(first)[:30], errors(nominal)[:30])
    # Hard pushes every few steps: the ruler sees the robot knocked over sooner than on nominal physics.
    shoves = dataclasses.replace(protocol.ranges, push_interval_s=(0.1, 0.2), push_max_speed=3.0)
    shoved = _randomized(standing, dataclasses.replace(protocol, ranges=shoves), 10_001)
    assert sum(r.steps for r in shoved) < sum(r.steps for r in nominal) - 20


def test_the_tracked_share_counts_steps_within_both_tolerances(standing: Standing) -> None:
    (rollout, *_) = _zero_grid(standing, None, [standing.model] * 3)
    joint = rollout.errors["E_mpjpe"] / 1000
    body = rollout.errors["E_mpbpe"] / 1000
    tolerance = TrackingTolerance(joint_rad=float(np.median(joint)), body_m=1.0)
    within = int((joint <= tolerance.joint_rad).sum())
    assert 0 < within < rollout.steps
    assert tracked_pct([rollout], tolerance) == round(100 * within / rollout.remaining_steps, 2)
    tight = TrackingTolerance(joint_rad=1.0, body_m=float(body.min()) / 2)
    assert tracked_pct([rollout], tight) == 0.0
    seconds = per_second(rollout, 50.0, TrackingTolerance(joint_rad=1.0, body_m=1.0))
    # 37 steps survived (`test_the_unbroken_prelude_lasts_past_the_break`): all tracked, in the first second.
    assert len(seconds) == 4 and seconds[0]["tracked_pct"] == round(100 * rollout.steps / 50, 1)
    assert seconds[1]["joint_rad"] is None and seconds[1]["tracked_pct"] == 0.0


@pytest.mark.slow
def test_the_pictures_show_the_rollout_moving_beside_its_reference(standing: Standing, tmp_path) -> None:
    (rollout, *_) = _zero_grid(standing, None, [standing.model] * 3)
    frames = np.arange(standing.reference.n_frames)
    root = standing.reference.body_names.index(standing.bodies.root)
    reference, _ = reference_states(standing.model, standing.reference, frames, root)
    assert rollout.qpos is not None
    scene = Scene("g1 standing prelude", rollout.qpos, reference, 50.0, rollout.ended_by)
    look = RenderConfig(width=160, height=120, filmstrip_frames=3, video_fps=10, video_max_s=2.0)
    pictures = render_pictures(standing.model, scene, look, tmp_path)
    assert pictures == {"filmstrip": "filmstrip.png", "video": "rollout.mp4"}, pictures
    assert sorted(p.name for p in tmp_path.iterdir()) == ["filmstrip.png", "rollout.mp4"]
    video = video_frames(tmp_path / "rollout.mp4")
    # Up to the rollout's end plus a second, at 10 frames a second, capped at 2 s.
    assert len(video) == min(20, -(-(rollout.steps + 51) // 5))
    assert all(frame.std() > 10 for frame in video)  # not blank
    motion = [np.abs(b.astype(int) - a).mean() for a, b in zip(video, video[1:])]
    assert max(motion) > 0.5  # the robots move
