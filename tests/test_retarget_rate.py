"""Solving the capture's own frames and resampling to the output rate (`ik.solve_at_capture_rate`)."""

from __future__ import annotations

import dataclasses

import numpy as np
from conftest import LAFAN_DIR

from rd_pipeline.motion.bvh import read_bvh
from rd_pipeline.motion.human import LAFAN_CM_TO_M, LAFAN_TO_Z_UP, human_motion_from_bvh
from rd_pipeline.retarget.config import RetargetConfig
from rd_pipeline.retarget.quality import retarget_quality
from rd_pipeline.retarget.retarget import retarget
from rd_pipeline.retarget.smoothing import resample_configurations
from rd_pipeline.robots import load_robot


def _pose(x: float, yaw: float) -> np.ndarray:
    return np.array([x, 0.0, 0.8, np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2), 2.0 * x])


def test_resampling_is_linear_between_solved_frames_and_keeps_the_quaternion_unit() -> None:
    solved = np.stack([_pose(0.0, 0.0), _pose(0.3, 0.6), _pose(0.6, 1.2)])
    read = resample_configurations(solved, 30.0, np.array([0.0, 1.0 / 60.0, 1.0 / 30.0, 1.0, 2.0 / 30.0]))
    np.testing.assert_allclose(read[:, 0], [0.0, 0.15, 0.3, 0.6, 0.6])
    np.testing.assert_allclose(read[:, 7], 2.0 * read[:, 0])
    np.testing.assert_allclose(np.linalg.norm(read[:, 3:7], axis=1), 1.0)
    # Halfway in time is halfway in yaw (the blend of two unit quaternions about one axis).
    np.testing.assert_allclose(2.0 * np.arctan2(read[1, 6], read[1, 3]), 0.3, atol=1e-3)


def test_resampling_is_no_faster_than_the_fastest_solved_step() -> None:
    rng = np.random.default_rng(0)
    solved = np.cumsum(rng.normal(size=(30, 8)), axis=0)
    solved[:, 3:7] = [1.0, 0.0, 0.0, 0.0]
    read = resample_configurations(solved, 30.0, np.arange(50) / 50.0)
    solved_speed = np.abs(np.diff(solved[:, 7])).max() * 30.0
    read_speed = np.abs(np.diff(read[:, 7])).max() * 50.0
    assert read_speed <= solved_speed + 1e-9


def test_a_clip_solved_at_its_capture_rate_comes_out_at_the_output_rate_within_the_bars() -> None:
    clip = human_motion_from_bvh(read_bvh(LAFAN_DIR / "dance1_subject2.bvh"), LAFAN_CM_TO_M, LAFAN_TO_Z_UP)
    frames = slice(round(11.0 * clip.fps), round(15.0 * clip.fps))
    clip = dataclasses.replace(clip, pos_w=clip.pos_w[frames], quat_w=clip.quat_w[frames])
    defaults = RetargetConfig()
    params = dataclasses.replace(defaults, ik=dataclasses.replace(defaults.ik, solve_at_capture_rate=True))
    robot = load_robot("g1")
    result = retarget(clip, robot, params)
    assert result.reference.fps == 50.0
    assert result.reference.n_frames == round(4.0 * 50.0)
    quality = retarget_quality(
        robot,
        result.reference,
        keypoint_targets=result.targets.positions,
        keypoint_bodies=result.targets.bodies,
        human_pelvis=result.targets.human_pelvis,
    )
    assert quality["keypoint_error_mean_mm"] < 60.0
    assert quality["skate_stance_mean_mm_s"] < 15.0
    for name in ("joint_limit_violations", "velocity_limit_violations", "self_collision_frames"):
        assert quality[name] == 0, name
