"""A mink limit that keeps every collision body of the robot above the floor plane z = 0."""

from __future__ import annotations

import mink
import mujoco
import numpy as np

from rd_pipeline.robots.hulls import BodyHulls


class FloorLimit(mink.Limit):
    """z_low(q) + J_z dq >= clearance for the lowest support point of each body near the floor.

    Only bodies within `detection_m` of the floor enter the QP, so a standing robot adds two rows
    (the feet). A body already below the clearance (linearization error of the previous step) must
    not go deeper; `relaxed` drops the demand to climb back, for the rare step where climbing is
    infeasible together with the per-frame joint and root bounds.
    """

    def __init__(self, model: mujoco.MjModel, hulls: BodyHulls, clearance_m: float, detection_m: float) -> None:
        self.model = model
        self.clearance = clearance_m
        self.detection = detection_m
        self.relaxed = False
        self.body_ids = hulls.body_ids
        self.points = np.concatenate(hulls.points)
        self.radii = np.concatenate(hulls.radii)
        self.owner = np.concatenate([np.full(len(p), k) for k, p in enumerate(hulls.points)])
        self.starts = np.concatenate([[0], np.cumsum([len(p) for p in hulls.points])[:-1]])
        self.jacobian = np.zeros((3, model.nv))

    def lowest_points(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """Per body: the world z of its lowest support point (radius included) and that point's index."""
        bodies = self.body_ids[self.owner]
        z_rows = data.xmat[bodies, 6:9]
        z = data.xpos[bodies, 2] + np.einsum("vi,vi->v", z_rows, self.points) - self.radii
        lowest = np.minimum.reduceat(z, self.starts)
        index = np.array([start + np.argmin(z[start:end]) for start, end in zip(self.starts, [*self.starts[1:], len(z)])])
        return lowest, index

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # a bound on the displacement itself
        data = configuration.data
        lowest, index = self.lowest_points(data)
        near = np.flatnonzero(lowest < self.clearance + self.detection)
        if len(near) == 0:
            return mink.Constraint()
        rows = np.empty((len(near), self.model.nv))
        h = np.empty(len(near))
        for row, k in enumerate(near):
            body = int(self.body_ids[k])
            point = data.xpos[body] + data.xmat[body].reshape(3, 3) @ self.points[index[k]]
            mujoco.mj_jac(self.model, data, self.jacobian, None, point, body)
            rows[row] = -self.jacobian[2]
            h[row] = lowest[k] - self.clearance
        if self.relaxed:
            h = np.maximum(h, 0.0)
        return mink.Constraint(G=rows, h=h)
