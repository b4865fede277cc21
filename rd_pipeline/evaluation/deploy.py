"""A deploy-style control loop: 50 Hz policy, 500 Hz physics, observations from raw simulator state.

It reads nothing but `policy.json`, the TorchScript policy, the reference motion and the robot's
MJCF, the way a robot-side loop would: joint positions and velocities, the pelvis quaternion and
angular velocity come from `qpos`/`qvel` by joint name, and the observation is assembled from the
layout in `policy.json`. Many rollouts (one per start frame) run side by side in the same C MuJoCo
backend that training uses on CPU (one physics implementation); one policy call serves all of them.
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np
import torch

from rd_pipeline.env.mdp.actions import ActionTargets
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.policy_spec import PolicySpec


def projected_gravity(quat_wxyz: np.ndarray) -> np.ndarray:
    """(R, 3) world -z expressed in the body frame of each (R, 4) orientation."""
    w, x, y, z = quat_wxyz.T
    # Third row of the rotation matrix, negated: R^T [0, 0, -1].
    return -np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1)


def reference_baseline_spec(spec: PolicySpec) -> PolicySpec:
    """The zero-action baseline's spec: the reference fed straight to PD whatever the policy's
    action semantics (on an absolute joint, a zero action would mean the default pose), i.e. zero
    residuals on every policy joint, with the observation layout resized to match."""
    joints = spec.get("joints.policy")
    observation = spec.get("observation")
    terms = [{**t, "size": len(joints)} if t["name"] == "last_action" else t for t in observation["terms"]]
    frame = sum(t["size"] for t in terms)
    return PolicySpec(
        {
            **spec.data,
            "action": {
                **spec.get("action"),
                "mode": "all",
                "outputs": joints,
                "semantics": ["residual"] * len(joints),
                "residual_mask": list(range(len(joints))),
            },
            "observation": {**observation, "terms": terms, "frame_size": frame, "size": frame * observation["history"]},
        }
    )


class DeployController:
    """Observation and action side of the loop for R rollouts at once."""

    def __init__(
        self,
        spec: PolicySpec,
        model: mujoco.MjModel,
        reference: ReferenceMotion,
        rollouts: int,
        noise: Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]] | None = None,
    ) -> None:
        self.spec = spec
        self.noise = noise
        """Adds sensor noise to an observation frame's terms (None: exact sensors)."""
        joints = spec.get("joints")
        actuated = joints["actuated"]
        policy = joints["policy"]
        self.qpos_idx = np.array([model.jnt_qposadr[model.joint(j).id] for j in policy])
        self.dof_idx = np.array([model.jnt_dofadr[model.joint(j).id] for j in policy])
        default = np.asarray(joints["default_pos"])
        self.default_actuated = default
        self.policy_in_actuated = np.array([actuated.index(j) for j in policy])
        self.default_policy = default[self.policy_in_actuated]
        self.outputs = np.array([policy.index(j) for j in spec.get("action.outputs")])
        action = spec.get("action")
        self.action_targets = ActionTargets(
            on_reference=torch.tensor([kind != "absolute" for kind in action["semantics"]]),
            outputs=torch.from_numpy(self.outputs),
            default_pos=torch.from_numpy(self.default_policy),
            lower=torch.tensor(joints["policy_lower"], dtype=torch.float64),
            upper=torch.tensor(joints["policy_upper"], dtype=torch.float64),
            scale=action["scale"],
            clip=action["clip"],
        )
        self.reference_joints = reference.joint_pos[:, [reference.joint_names.index(j) for j in policy]]
        self.terms = spec.get("observation.terms")
        self.history = spec.get("observation.history")
        self.future_steps = np.asarray(spec.data["observation"].get("ref_future_steps", []), dtype=np.int64)
        self.rollouts = rollouts
        self.frame = np.zeros(rollouts, dtype=np.int64)
        self.last_action = np.zeros((rollouts, len(self.outputs)))
        self.frames = np.zeros((rollouts, self.history, spec.get("observation.frame_size")), dtype=np.float32)

    def _next_frame(self) -> np.ndarray:
        return np.minimum(self.frame + 1, len(self.reference_joints) - 1)

    def _future(self) -> np.ndarray:
        """(R, K * P) the reference joints `ref_future_steps` control steps ahead, nearest first."""
        ahead = np.minimum(self.frame[:, None] + self.future_steps, len(self.reference_joints) - 1)
        return self.reference_joints[ahead].reshape(self.rollouts, -1)

    def _frame(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        values = {
            "joint_pos": qpos[:, self.qpos_idx] - self.default_policy,
            "joint_vel": qvel[:, self.dof_idx],
            "projected_gravity": projected_gravity(qpos[:, 3:7]),
            "base_ang_vel": qvel[:, 3:6],
            "last_action": self.last_action,
            "ref_joint_pos_next": self.reference_joints[self._next_frame()],
            "ref_joint_pos_future": self._future(),
        }
        if self.noise is not None:
            values = self.noise(values)
        return np.concatenate([t["scale"] * values[t["name"]] for t in self.terms], axis=-1)

    def reset(self, qpos: np.ndarray, qvel: np.ndarray, frames: np.ndarray) -> None:
        """Start every rollout at reference frame `frames[r]`; the history starts full of the first frame."""
        self.frame = frames.astype(np.int64).copy()
        self.last_action[:] = 0.0
        self.frames[:] = self._frame(qpos, qvel)[:, None]

    def observe(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        """Push the current frame into the history; (R, observation_size), oldest frame first."""
        self.frames = np.concatenate([self.frames[:, 1:], self._frame(qpos, qvel)[:, None]], axis=1)
        return self.frames.reshape(self.rollouts, -1)

    def current(self) -> np.ndarray:
        return self.frames.reshape(self.rollouts, -1)

    def targets(self, action: np.ndarray) -> np.ndarray:
        """(R, actuated) PD targets for this control step, per `policy.json`'s action block; advances the frame."""
        reference_next = torch.from_numpy(self.reference_joints[self._next_frame()])
        actions = torch.from_numpy(np.asarray(action, dtype=np.float64))
        policy_targets = self.action_targets(actions, reference_next).numpy()
        ctrl = np.tile(self.default_actuated, (self.rollouts, 1))
        ctrl[:, self.policy_in_actuated] = policy_targets
        self.last_action = np.asarray(action, dtype=np.float64).copy()
        self.frame = self._next_frame()
        return ctrl
