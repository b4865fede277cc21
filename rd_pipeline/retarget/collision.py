"""The QP's collision avoidance between the robot config's body pairs (mink's limit, on every geom
the step check counts), and the easing back of a pose that a pass after the QP took into contact."""

from __future__ import annotations

import copy

import mink
import mujoco
import numpy as np

from rd_pipeline.errors import PipelineError
from rd_pipeline.retarget.config import IkConfig
from rd_pipeline.retarget.quality import colliding_frames
from rd_pipeline.retarget.smoothing import blend_configurations
from rd_pipeline.robots import Robot
from rd_pipeline.robots.model import collision_geom_pairs, collision_geoms


def collision_limit(robot: Robot, settings: IkConfig) -> mink.CollisionAvoidanceLimit | None:
    """Collision avoidance between the config's body pairs (None when it pairs none)."""
    pairs = pair_geoms(robot)
    if not pairs:
        return None
    avoidance = mink.CollisionAvoidanceLimit(
        colliding_copy(robot.model, pairs),
        pairs,
        minimum_distance_from_collisions=settings.collision_margin_m,
        collision_detection_distance=settings.collision_detection_m,
    )
    require_same_pairs(robot, avoidance)
    return avoidance


def pair_geoms(robot: Robot) -> list[tuple[list[int], list[int]]]:
    """The geoms of each body pair of the config, as mink's collision limit takes them."""
    model = robot.model
    return [
        (collision_geoms(model, robot.body_ids[a]), collision_geoms(model, robot.body_ids[b]))
        for a, b in robot.config.collision_pairs
    ]


def require_same_pairs(robot: Robot, avoidance: mink.CollisionAvoidanceLimit) -> None:
    """The QP must avoid every geom pair the step check counts; mink also skips bodies welded
    together or parent and child, which a robot config should not pair."""
    checked = {tuple(sorted(pair)) for pair in collision_geom_pairs(robot).tolist()}
    avoided = {tuple(sorted(pair)) for pair in avoidance.geom_id_pairs}
    if checked != avoided:
        first, second = sorted(checked - avoided)[0]
        model = robot.model
        bodies = (model.body(model.geom_bodyid[first]).name, model.body(model.geom_bodyid[second]).name)
        raise PipelineError(
            f"{robot.config.source}: collision pair {bodies} cannot be kept apart by the IK "
            "(welded, or parent and child); remove it from [collision] pairs"
        )


def colliding_copy(model: mujoco.MjModel, pairs: list[tuple[list[int], list[int]]]) -> mujoco.MjModel:
    """`model` with every geom of the configured pairs marked as colliding, for the QP's collision
    limit. mink drops pairs that fail MuJoCo's contype/conaffinity test, and some hands are visual
    geoms only (H1-2's wrists) that the step check (`RetargetIk._pair_depth`) counts all the same: the QP then
    steers a wrist into the torso and the step check refuses every step after, freezing the pose."""
    marked = copy.deepcopy(model)
    for geom in {g for first, second in pairs for g in (*first, *second)}:
        marked.geom_contype[geom] |= 1
        marked.geom_conaffinity[geom] |= 1
    return marked


def eased_until_clear(robot: Robot, pose: np.ndarray, toward: np.ndarray, depth_m: float) -> np.ndarray:
    """`pose` (nq,) blended towards `toward` a quarter at a time until no configured body pair is
    deeper than `depth_m` (at most all the way to `toward`)."""
    for weight in (0.25, 0.5, 0.75, 1.0):
        candidate = blend_configurations(pose[None], toward[None], np.array([weight]))[0]
        if not colliding_frames(robot, candidate[None], depth_m)[0]:
            break
    return candidate
