"""The postures the first frame of a retarget may start from."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rd_pipeline.errors import PipelineError
from rd_pipeline.params import ParamRangeError
from rd_pipeline.retarget.config import IkConfig
from rd_pipeline.retarget.start_postures import start_postures
from rd_pipeline.robots import load_robot


@pytest.mark.parametrize("name", ["g1", "h1", "h1_2"])
def test_only_the_knees_fold_and_towards_their_flexion_end(name: str) -> None:
    robot = load_robot(name)
    default, half, folded = start_postures(robot, (0.0, 0.5, 1.0))
    np.testing.assert_array_equal(default, robot.config.default_pos)
    moved = np.flatnonzero(folded != default)
    assert [robot.config.joint_names[k] for k in moved] == ["left_knee_joint", "right_knee_joint"]
    model = robot.model
    for k in moved:
        low, high = model.jnt_range[model.joint(robot.config.joint_names[k]).id]
        # Every knee here bends further forward than back: it folds to its upper end.
        assert high > abs(low)
        assert folded[k] == pytest.approx(high)
        assert half[k] == pytest.approx((default[k] + high) / 2)


def test_a_knee_body_that_no_listed_joint_moves_is_named() -> None:
    robot = load_robot("g1")
    retarget_map = dict(robot.config.retarget_map)
    del retarget_map["left_knee_link"]
    retarget_map["world"] = "LeftLeg"
    robot = dataclasses.replace(robot, config=dataclasses.replace(robot.config, retarget_map=retarget_map))
    with pytest.raises(PipelineError, match="the knee body 'world' is not moved by one of joints.names"):
        start_postures(robot, (0.0, 0.85))


@pytest.mark.parametrize("bends", [(), (0.0, 1.5), (-0.1,)])
def test_knee_bends_outside_zero_to_one_are_refused(bends: tuple[float, ...]) -> None:
    with pytest.raises(ParamRangeError, match="start_knee_bends"):
        IkConfig(start_knee_bends=bends)
