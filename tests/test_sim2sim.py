"""What ends a sim2sim rollout: a reference broken on purpose at a known frame and body must end
the rollout there, named by the failure it broke."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import RETARGETED_DIR

from rd_pipeline.evaluation.deploy import reference_baseline_spec
from rd_pipeline.evaluation.protocol import Protocol
from rd_pipeline.evaluation.sim2sim import BodySets, Rollout, run_rollouts
from rd_pipeline.evaluation.validation import deploy_model
from rd_pipeline.export.exporter import build_policy_spec
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.rl.env_config import EnvConfig
from rd_pipeline.robots import load_robot

BROKEN_AT = 20
"""The frame from which the broken references leave the robot behind (0.4 s in)."""


@pytest.fixture(scope="module")
def standing():
    """G1 dance1_subject2's first 4 s (dataset CSV, standing prelude), where the reference fed to PD
    (zero action) stays within the limits past `BROKEN_AT` (0.74 s, then its left hand lags), and
    what the rollouts run on."""
    robot = load_robot("g1")
    path = RETARGETED_DIR / "g1" / "dance1_subject2.csv"
    reference = import_retargeted_csv(path, robot, 30.0, 50.0, "cubic", ContactThresholds()).reference.frames(0, 200)
    policy_joints = len(robot.config.policy_joints)
    spec = reference_baseline_spec(
        build_policy_spec(robot, EnvConfig(), policy_joints, "import", "k", (0, reference.n_frames))
    )
    rc = robot.config
    bodies = BodySets(rc.root_body, rc.tracking_bodies, rc.termination_bodies, rc.foot_bodies)
    return reference, spec, deploy_model(spec), bodies


def _rollout(standing, reference: ReferenceMotion) -> Rollout:
    _, spec, model, bodies = standing
    joints = len(spec.get("joints.policy"))

    def zero(obs: np.ndarray) -> np.ndarray:
        return np.zeros((len(obs), joints), dtype=np.float32)

    (rollout,) = run_rollouts(spec, [model], reference, zero, np.array([0]), bodies, Protocol())
    return rollout


def test_the_unbroken_prelude_lasts_past_the_break(standing) -> None:
    rollout = _rollout(standing, standing[0])
    assert rollout.steps > BROKEN_AT + 10
    assert rollout.completed == (rollout.ended_by == "")


def test_a_hand_the_reference_lifts_away_ends_the_rollout_as_far(standing) -> None:
    reference = standing[0]
    hand = reference.body_names.index("left_wrist_roll_rubber_hand")
    body_pos = reference.body_pos_w.copy()
    body_pos[BROKEN_AT:, hand, 2] += 1.0
    rollout = _rollout(standing, dataclasses.replace(reference, body_pos_w=body_pos))
    assert rollout.ended_by == "far left_wrist_roll_rubber_hand"
    assert rollout.steps == BROKEN_AT
    assert not rollout.completed


def test_a_reference_that_tips_over_ends_the_rollout_as_tilted(standing) -> None:
    reference = standing[0]
    pelvis = reference.body_names.index("pelvis")
    body_quat = reference.body_quat_w.copy()
    body_quat[BROKEN_AT:, pelvis] = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]  # 90 degrees about x
    rollout = _rollout(standing, dataclasses.replace(reference, body_quat_w=body_quat))
    assert rollout.ended_by == "tilted"
    assert rollout.steps == BROKEN_AT
