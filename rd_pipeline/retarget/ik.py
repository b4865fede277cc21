"""Frame-by-frame IK with mink: key-body frame tasks, posture regularization, hard limits, warm start."""

from __future__ import annotations

from collections.abc import Iterable

import mink
import mujoco
import numpy as np

from rd_pipeline.retarget.limits import FrameStepLimit
from rd_pipeline.retarget.settings import IkSettings, IkWeights
from rd_pipeline.retarget.targets import RetargetTargets
from rd_pipeline.robots import Robot
from rd_pipeline.robots.model import collision_geoms


class RetargetIk:
    """One mink problem reused for every frame."""

    def __init__(self, robot: Robot, targets: RetargetTargets, weights: IkWeights, settings: IkSettings) -> None:
        self.robot, self.targets, self.settings = robot, targets, settings
        model = robot.model
        self.configuration = mink.Configuration(model)
        config = robot.config
        oriented = set(targets.orientations)
        feet = set(config.foot_bodies)
        self.frame_tasks: list[mink.FrameTask] = []
        for body in targets.bodies:
            if body == config.root_body:
                cost = (weights.root_position, weights.root_orientation)
            elif body in feet:
                cost = (weights.feet_position, weights.feet_orientation)
            elif body in oriented:
                cost = (weights.limb_position, weights.torso_orientation)
            else:
                cost = (weights.limb_position, 0.0)
            self.frame_tasks.append(mink.FrameTask(
                body, "body", position_cost=cost[0], orientation_cost=cost[1], lm_damping=settings.lm_damping,
            ))
        self.posture = mink.PostureTask(model, cost=weights.posture)
        q_default = self.configuration.q.copy()
        q_default[robot.qpos_indices] = config.default_pos
        self.posture.set_target(q_default)
        frame_period = 1.0 / targets.fps
        self.step_limit = FrameStepLimit(
            robot.dof_indices, robot.joint_range[:, 0], robot.joint_range[:, 1], robot.qpos_indices, model.nv,
            config.velocity_limit * frame_period * settings.velocity_margin,
            np.array([settings.root_speed_m_s] * 3 + [settings.root_angular_speed_rad_s] * 3) * frame_period,
        )
        pairs = [
            (collision_geoms(model, robot.body_ids[a]), collision_geoms(model, robot.body_ids[b]))
            for a, b in config.collision_pairs
        ]
        self.limits: list[mink.Limit] = [self.step_limit]
        if pairs:
            self.limits.append(mink.CollisionAvoidanceLimit(
                model, pairs, minimum_distance_from_collisions=settings.collision_margin_m,
                collision_detection_distance=settings.collision_detection_m,
            ))
        self.tasks = [*self.frame_tasks, self.posture]
        self.damping = weights.damping

    def initial_configuration(self) -> np.ndarray:
        """Default pose placed at the first frame's pelvis target."""
        q = self.configuration.q.copy()
        q[:] = 0.0
        q[3] = 1.0
        q[self.robot.qpos_indices] = self.robot.config.default_pos
        root = self.targets.bodies.index(self.robot.config.root_body)
        q[:3] = self.targets.positions[0, root]
        rotation = self.targets.orientations.get(self.robot.config.root_body)
        if rotation is not None:
            mujoco.mju_mat2Quat(q[3:7], rotation[0].reshape(-1))
        return q

    def _set_frame_targets(self, t: int) -> None:
        targets = self.targets
        for task, body in zip(self.frame_tasks, targets.bodies):
            rotation = targets.orientations.get(body)
            so3 = mink.SO3.from_matrix(rotation[t]) if rotation is not None else mink.SO3.identity()
            task.set_target(mink.SE3.from_rotation_and_translation(so3, targets.positions[t, targets.bodies.index(body)]))

    def refine_feet(self, smoothed: np.ndarray, frames: Iterable[int]) -> np.ndarray:
        """Put the feet of a smoothed trajectory back on their targets, moving the legs only.

        Each frame starts from the smoothed pose, with the base fixed and a posture task holding
        every joint near its smoothed value, so the smoothness survives where the feet need no help.
        """
        feet = set(self.robot.config.foot_bodies)
        foot_tasks = [task for task, body in zip(self.frame_tasks, self.targets.bodies) if body in feet]
        hold = mink.PostureTask(self.robot.model, cost=self.settings.refine_posture_cost)
        out = smoothed.copy()
        previous = None
        for t in frames:
            self._set_frame_targets(t)
            hold.set_target(smoothed[t])
            self.configuration.update(smoothed[t])
            self.step_limit.start_frame(previous)
            self.step_limit.root_budget = np.zeros(6)
            for _ in range(self.settings.refine_iterations):
                velocity = mink.solve_ik(
                    self.configuration, [*foot_tasks, hold], 1.0, self.settings.solver, damping=self.damping,
                    limits=self.limits,
                )
                self.configuration.integrate_inplace(velocity, 1.0)
            out[t] = self._clipped(self.configuration.q)
            previous = out[t]
        return out

    def _clipped(self, q: np.ndarray) -> np.ndarray:
        q = q.copy()
        q[self.robot.qpos_indices] = np.clip(q[self.robot.qpos_indices], self.step_limit.lower, self.step_limit.upper)
        return q

    def solve(self, frames: Iterable[int]) -> np.ndarray:
        """(T, nq) configurations, frame by frame."""
        targets = self.targets
        out = np.empty((targets.n_frames, self.robot.model.nq))
        self.configuration.update(self.initial_configuration())
        previous = None
        for t in frames:
            self._set_frame_targets(t)
            self.step_limit.start_frame(previous)
            # The first frame starts from the default pose, so it gets more iterations to converge.
            for _ in range(self.settings.iterations if previous is not None else 50):
                velocity = mink.solve_ik(
                    self.configuration, self.tasks, 1.0, self.settings.solver, damping=self.damping, limits=self.limits,
                )
                self.configuration.integrate_inplace(velocity, 1.0)
                self.step_limit.spend_root_step(velocity[:6])
            out[t] = self._clipped(self.configuration.q)
            previous = out[t]
        return out
