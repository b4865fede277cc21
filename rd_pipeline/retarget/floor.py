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
        self.hulls = hulls
        self.points = hulls.points
        self.radii = hulls.radii
        self.jacobian = np.zeros((3, model.nv))
        self.extra = np.zeros(len(self.body_ids))

    def raise_bodies(self, extra_m: np.ndarray) -> None:
        """Per body, clearance beyond the floor's for the next solves (a swinging foot's lift)."""
        self.extra = extra_m

    def lowest_points(self, data: mujoco.MjData, within_m: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """Per body: the world z of its lowest support point (radius included) and that point's index.

        Bodies that cannot come within `within_m` of the floor report the bound that says so
        (`BodyHulls.lowest_bound`) and index -1.
        """
        origin_z = data.xpos[self.body_ids, 2]
        z_rows = data.xmat[self.body_ids, 6:9]
        lowest = self.hulls.lowest_bound(origin_z, z_rows)
        index = np.full(len(self.body_ids), -1)
        for k in np.flatnonzero(lowest < within_m):
            z = origin_z[k] + self.points[k] @ z_rows[k] - self.radii[k]
            index[k] = int(np.argmin(z))
            lowest[k] = z[index[k]]
        return lowest, index

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # a bound on the displacement itself
        data = configuration.data
        clearance = self.clearance + self.extra
        lowest, index = self.lowest_points(data, float(clearance.max()) + self.detection)
        near = np.flatnonzero((lowest < clearance + self.detection) & (index >= 0))
        if len(near) == 0:
            return mink.Constraint()
        rows = np.empty((len(near), self.model.nv))
        h = np.empty(len(near))
        for row, k in enumerate(near):
            body = int(self.body_ids[k])
            point = data.xpos[body] + data.xmat[body].reshape(3, 3) @ self.points[k][index[k]]
            mujoco.mj_jac(self.model, data, self.jacobian, None, point, body)
            rows[row] = -self.jacobian[2]
            h[row] = lowest[k] - clearance[k]
        if self.relaxed:
            h = np.maximum(h, 0.0)
        return mink.Constraint(G=rows, h=h)
