"""The IK's tasks: a frame task per key body, with its target poses and per-frame position costs,
and the posture that holds the joints the key bodies leave free."""

from __future__ import annotations

import mink
import mujoco
import numpy as np

from rd_pipeline.retarget.config import IkWeights
from rd_pipeline.retarget.smoothing import smoothstep
from rd_pipeline.retarget.targets import RetargetTargets
from rd_pipeline.robots import Robot
from rd_pipeline.robots.config import RobotConfig


def frame_tasks(
    targets: RetargetTargets,
    config: RobotConfig,
    weights: IkWeights,
    lm_damping: float,
) -> list[mink.FrameTask]:
    """One frame task per key body, in `targets.bodies` order; bodies without an orientation
    target get no orientation cost."""
    oriented = set(targets.orientations)
    feet = set(config.foot_bodies)
    tasks: list[mink.FrameTask] = []
    for body in targets.bodies:
        if body == config.root_body:
            orientation_cost = weights.root_orientation
        elif body in feet:
            orientation_cost = weights.feet_orientation
        elif body in oriented:
            orientation_cost = weights.torso_orientation
        else:
            orientation_cost = 0.0
        tasks.append(
            mink.FrameTask(
                body,
                "body",
                position_cost=1.0,
                orientation_cost=orientation_cost,
                lm_damping=lm_damping,
            )
        )
    return tasks


def target_poses(targets: RetargetTargets) -> np.ndarray:
    """(T, K, 7) wxyz_xyz target poses of the key bodies; bodies without an orientation target get
    the identity, which their tasks do not weigh."""
    poses = np.zeros((targets.n_frames, len(targets.bodies), 7))
    poses[..., 0] = 1.0
    poses[..., 4:] = targets.positions
    for k, body in enumerate(targets.bodies):
        rotation = targets.orientations.get(body)
        if rotation is None:
            continue
        for t in range(targets.n_frames):
            mujoco.mju_mat2Quat(poses[t, k, :4], rotation[t].reshape(-1))
    return poses


def posture_task(robot: Robot, configuration: mink.Configuration, cost: float) -> mink.PostureTask:
    """Pulls every joint toward the robot's default pose."""
    posture = mink.PostureTask(robot.model, cost=cost)
    q_default = configuration.q.copy()
    q_default[robot.qpos_indices] = robot.config.default_pos
    posture.set_target(q_default)
    return posture


def position_cost_schedule(targets: RetargetTargets, config: RobotConfig, weights: IkWeights) -> np.ndarray:
    """(T, K, 3) position cost of each key body per frame, along its own axes.

    Planted feet must not slide; swinging feet only guide the leg sideways, so the body follows the
    pelvis rather than a foot it cannot reach. Bodies resting on the floor are held like planted feet.
    Along the pelvis' own up axis the cost is higher: sinking is the cheapest way out of a conflict
    between the feet and the legs, and it reads as a collapse.
    """
    n_frames = targets.n_frames
    costs = np.full((n_frames, len(targets.bodies), 3), weights.limb_position)
    costs[targets.body_contact] = weights.contact_position
    root = targets.bodies.index(config.root_body)
    costs[:, root] = [weights.root_position, weights.root_position, weights.root_height]
    resting = targets.body_contact[:, root]
    costs[resting, root] = np.maximum(costs[resting, root], weights.contact_position)
    for side, foot in enumerate(config.foot_bodies):
        k = targets.bodies.index(foot)
        # A swinging foot's target first rises to its clearance, then travels. Until it has risen
        # the foot is held along the floor like a planted one: any slide there reads as skate.
        risen = targets.foot_lift[:, side] / targets.swing_clearance_m
        lifted = smoothstep(1.0 - (1.0 - risen) / weights.swing_cost_ramp)
        swing = weights.feet_position + lifted * (weights.swing_feet_position - weights.feet_position)
        costs[:, k, :2] = np.where(targets.foot_contact[:, side], weights.feet_position, swing)[:, None]
        # Along its own up axis a swinging foot keeps the planted cost: it clears the floor as its
        # target does instead of dragging along it.
        costs[:, k, 2] = weights.feet_position
    return costs
