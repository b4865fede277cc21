"""What ends a sim2sim rollout: a reference broken on purpose at a known frame and body must end
the rollout there, named by the failure it broke."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import mujoco
import numpy as np
import pytest
from conftest import RETARGETED_DIR

from rd_pipeline.errors import PipelineError
from rd_pipeline.evaluation.deploy import reference_baseline_spec
from rd_pipeline.evaluation.protocol import Protocol
from rd_pipeline.evaluation.sim2sim import BodySets, Rollout, run_rollouts
from rd_pipeline.evaluation.validation import deploy_model
from rd_pipeline.export.exporter import build_policy_spec
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.policy_spec import PolicySpec
from rd_pipeline.rl.env_config import EnvConfig
from rd_pipeline.robots import load_robot

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
