"""A mink limit that bounds each joint by its range and by how far it may move in one frame period."""

from __future__ import annotations

import mink
import numpy as np


class FrameStepLimit(mink.Limit):
    """lower <= q + dq <= upper with bounds = joint range intersected with q_prev +- v_max * T.

    mink's VelocityLimit bounds one solver step at the solver's dt; here several solver iterations
    share one frame, so the bound is on the displacement from the previous *frame*. That makes the
    finite-difference velocity of the output obey the limits by construction.
    """

    def __init__(
        self,
        dof_indices: np.ndarray,
        lower: np.ndarray,
        upper: np.ndarray,
        qpos_indices: np.ndarray,
        nv: int,
        max_step: np.ndarray,
    ) -> None:
        self.dof_indices = dof_indices
        self.qpos_indices = qpos_indices
        self.range_lower = lower
        self.range_upper = upper
        self.max_step = max_step
        self.lower = lower.copy()
        self.upper = upper.copy()
        self.projection = np.zeros((len(dof_indices), nv))
        self.projection[np.arange(len(dof_indices)), dof_indices] = 1.0
        # The floating base (dofs 0-5) gets a per-frame step bound too: otherwise, when joints hit
        # their rate limit, the solver throws the whole body around to reach the targets.
        self.root_projection = np.zeros((6, nv))
        self.root_projection[np.arange(6), np.arange(6)] = 1.0
        self.root_budget = np.full(6, np.inf)
        self.G = np.vstack([self.projection, -self.projection, self.root_projection, -self.root_projection])

    def start_frame(self, previous_q: np.ndarray | None, root_max_step: np.ndarray) -> None:
        """Bounds for the next frame, around the previous frame's joint positions; the floating base
        may move by `root_max_step` (6,) per tangent axis in this frame."""
        self.root_budget = root_max_step.copy()
        if previous_q is None:
            self.lower = self.range_lower.copy()
            self.upper = self.range_upper.copy()
            return
        joints = previous_q[self.qpos_indices]
        self.lower = np.maximum(self.range_lower, joints - self.max_step)
        self.upper = np.minimum(self.range_upper, joints + self.max_step)

    def narrow(self, lower: np.ndarray, upper: np.ndarray) -> None:
        """Keep this frame's joints also within [lower, upper], where that band meets the bounds."""
        narrowed_lower = np.maximum(self.lower, lower)
        narrowed_upper = np.minimum(self.upper, upper)
        meets = narrowed_lower <= narrowed_upper
        self.lower = np.where(meets, narrowed_lower, self.lower)
        self.upper = np.where(meets, narrowed_upper, self.upper)

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # bounds are on the displacement itself
        joints = configuration.q[self.qpos_indices]
        # A small inward margin keeps the solution inside despite solver tolerances.
        h = np.concatenate([self.upper - joints, joints - self.lower]) - 1e-7
        root = np.minimum(self.root_budget, 1e6)
        return mink.Constraint(G=self.G, h=np.concatenate([np.maximum(h, 0.0), root, root]))

    def spend_root_step(self, root_velocity: np.ndarray) -> None:
        """Iterations within a frame share the frame's root step budget."""
        self.root_budget = np.maximum(self.root_budget - np.abs(root_velocity), 0.0)
