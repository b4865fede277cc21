"""The IK's tasks: mink's frame task on every key body (batched into one task), with its target
poses and per-frame position costs, and the posture that holds the joints the key bodies leave free."""

from __future__ import annotations

import mink
import mujoco
import numpy as np

# mink's native Lie operations, which its FrameTask uses: the same arithmetic, to the bit.
from mink.lie import _lie_ops_c as lie

from rd_pipeline.retarget.config import IkWeights
from rd_pipeline.retarget.smoothing import smoothstep
from rd_pipeline.retarget.targets import RetargetTargets
from rd_pipeline.robots import Robot
from rd_pipeline.robots.config import RobotConfig


class KeyBodiesTask(mink.Task):
    """mink.FrameTask on each of several bodies, as one task.

    The error and Jacobian of each body are FrameTask's, computed with the same native Lie
    operations in the same order, and stacked in body order: the QP is the one a list of frame
    tasks builds, bit for bit. One task instead of a dozen cuts the Python work of assembling
    each QP (a third of a retarget's time on G1 floor work) by about half.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        body_ids: np.ndarray,
        orientation_costs: np.ndarray,
        lm_damping: float,
    ) -> None:
        cost = np.ones((len(body_ids), 6))
        cost[:, 3:] = np.asarray(orientation_costs)[:, None]
        # The task's cost is a view of the per-body costs: setting one sets the other.
        super().__init__(cost=cost.reshape(-1), lm_damping=lm_damping)
        self.model = model
        self.body_ids = [int(body) for body in body_ids]
        self.body_costs = cost
        self.targets = np.zeros((len(body_ids), 7))
        self.targets[:, 0] = 1.0
        count = len(body_ids)
        self.world_jacobians = np.empty((count, 6, model.nv))
        self.log_jacobians = np.empty((count, 6, 6))
        self.errors = np.empty(6 * count)
        self.jacobians = np.empty((6 * count, model.nv))

    def set_targets(self, poses: np.ndarray) -> None:
        """(K, 7) wxyz_xyz target pose of each body."""
        self.targets[:] = poses

    def set_position_costs(self, costs: np.ndarray) -> None:
        """(K, 3) position cost of each body along its own axes."""
        self.body_costs[:, :3] = costs

    def select(self, columns: list[int]) -> KeyBodiesTask:
        """A task over some of the bodies, with their costs; its targets are set separately."""
        orientation_costs = self.body_costs[columns, 3]
        return KeyBodiesTask(self.model, np.array(self.body_ids)[columns], orientation_costs, self.lm_damping)

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        return self._errors_and_jacobians(configuration)[0].copy()

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        return self._errors_and_jacobians(configuration)[1].copy()

    def compute_qp_residual(self, configuration: mink.Configuration) -> tuple[np.ndarray, np.ndarray, float]:
        errors, jacobians = self._errors_and_jacobians(configuration)
        weighted_errors = self.cost * (-self.gain * errors)
        weighted_jacobians = self.cost[:, None] * jacobians
        # Each body's squared error as its own dot product (a stacked matmul), summed body by
        # body, as mink sums the frame tasks' terms.
        body_errors = weighted_errors.reshape(-1, 6)
        squared = np.matmul(body_errors[:, None, :], body_errors[:, :, None]).ravel()
        mu = 0.0
        for body_squared in squared.tolist():
            mu += self.lm_damping * body_squared
        return weighted_jacobians, weighted_errors, mu

    def _errors_and_jacobians(self, configuration: mink.Configuration) -> tuple[np.ndarray, np.ndarray]:
        """(6K,) body twists to the targets and (6K, nv) their Jacobians, in the body frames."""
        data = configuration.data
        errors = self.errors.reshape(-1, 6)
        for k, (body, target) in enumerate(zip(self.body_ids, self.targets)):
            xmat = data.xmat[body]
            frame = lie.xmat_xpos_to_wxyz_xyz(xmat, data.xpos[body])
            jacobian = self.world_jacobians[k]
            mujoco.mj_jacBody(self.model, data, jacobian[:3], jacobian[3:], body)
            errors[k] = lie.se3_rminus(target, frame)
            self.log_jacobians[k] = lie.se3_jlog(lie.se3_inverse_multiply(target, frame))
        # FrameTask's products per body, stacked: the world Jacobian into the body frame (its
        # rotation adjoint is R^T on the linear and the angular rows, the same numbers as mink's
        # 6x6 product), then through the log's Jacobian.
        count = len(self.body_ids)
        to_body = data.xmat[self.body_ids].reshape(count, 1, 3, 3).transpose(0, 1, 3, 2)
        world = self.world_jacobians.reshape(count, 2, 3, -1)
        body_jacobians = np.matmul(to_body, world).reshape(count, 6, -1)
        np.negative(self.log_jacobians, out=self.log_jacobians)
        np.matmul(self.log_jacobians, body_jacobians, out=self.jacobians.reshape(count, 6, -1))
        return self.errors, self.jacobians


def key_bodies_task(
    robot: Robot,
    targets: RetargetTargets,
    weights: IkWeights,
    lm_damping: float,
) -> KeyBodiesTask:
    """The task over every key body, in `targets.bodies` order; bodies without an orientation
    target get no orientation cost."""
    config = robot.config
    oriented = set(targets.orientations)
    feet = set(config.foot_bodies)
    orientation_costs = []
    for body in targets.bodies:
        if body == config.root_body:
            orientation_costs.append(weights.root_orientation)
        elif body in feet:
            orientation_costs.append(weights.feet_orientation)
        elif body in oriented:
            orientation_costs.append(weights.torso_orientation)
        else:
            orientation_costs.append(0.0)
    body_ids = np.array([robot.body_ids[body] for body in targets.bodies])
    return KeyBodiesTask(robot.model, body_ids, np.array(orientation_costs), lm_damping)


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
    In height the pelvis is held more closely than across (`_root_costs`): sinking is the
    cheapest way out of a conflict between the feet and the legs, and it reads as a collapse.
    """
    n_frames = targets.n_frames
    costs = np.full((n_frames, len(targets.bodies), 3), weights.limb_position)
    costs[targets.body_contact] = weights.contact_position
    root = targets.bodies.index(config.root_body)
    costs[:, root] = _root_costs(targets, config, weights)
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


def _root_costs(targets: RetargetTargets, config: RobotConfig, weights: IkWeights) -> np.ndarray:
    """(T, 3) pelvis position cost along its own axes: `root_height` along its up axis and along
    whichever axis of its target stands upright, `root_position` along the others.

    A tilted axis gets the part of `root_height` its vertical component's square gives it (the
    axes' squares sum to one). Held by its own up axis alone, a pelvis tipped by sitting back or
    crawling had its height weighed at about half (H1 on ground2's floor cuts: 0.2-0.25 m over
    the scaled hips); with the vertical's cost in place of the up axis' instead of beside it, the
    lying pelvis of H1's fall on pushAndFall1_subject4 132-152 s drifted and its feet slid
    (skate 9.9 -> 15.1 mm/s)."""
    # Columns of a rotation are its body's axes in the world: row 2 holds their vertical parts.
    vertical_share = targets.orientations[config.root_body][:, 2, :] ** 2
    vertical = weights.root_position + (weights.root_height - weights.root_position) * vertical_share
    upright = np.array([weights.root_position, weights.root_position, weights.root_height])
    return np.maximum(vertical, upright)
