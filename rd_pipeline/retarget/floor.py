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

    def __init__(
        self,
        model: mujoco.MjModel,
        hulls: BodyHulls,
        clearance_m: float,
        detection_m: float,
        support_reuse: float = 0.0,
    ) -> None:
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
        self.candidates = [SupportCandidates(p, r, support_reuse) for p, r in zip(hulls.points, hulls.radii)]

    def raise_bodies(self, extra_m: np.ndarray) -> None:
        """Per body, clearance beyond the floor's for the next solves (a swinging foot's lift)."""
        self.extra = extra_m

    def lowest_points(
        self,
        data: mujoco.MjData,
        within_m: float | np.ndarray = np.inf,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per body: the world z of its lowest support point (radius included) and that point's index.

        Bodies that cannot come within `within_m` (one distance, or one per body) of the floor
        report the bound that says so (`BodyHulls.lowest_bound`) and index -1.
        """
        origin_z = data.xpos[self.body_ids, 2]
        z_rows = data.xmat[self.body_ids, 6:9]
        lowest = self.hulls.lowest_bound(origin_z, z_rows)
        index = np.full(len(self.body_ids), -1)
        for k in np.flatnonzero(lowest < within_m):
            index[k], lowest[k] = self.candidates[k].lowest(origin_z[k], z_rows[k])
        return lowest, index

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        del dt  # a bound on the displacement itself
        data = configuration.data
        clearance = self.clearance + self.extra
        lowest, index = self.lowest_points(data, clearance + self.detection)
        near = np.flatnonzero((lowest < clearance + self.detection) & (index >= 0))
        if len(near) == 0:
            return mink.Constraint()
        bodies = self.body_ids[near]
        local = np.array([self.points[k][index[k]] for k in near])
        # One stacked product: each row is the matrix-vector product of one body, as alone.
        rotated = np.matmul(data.xmat[bodies].reshape(-1, 3, 3), local[:, :, None])[:, :, 0]
        points = data.xpos[bodies] + rotated
        rows = np.empty((len(near), self.model.nv))
        for row, body in enumerate(bodies.tolist()):
            mujoco.mj_jac(self.model, data, self.jacobian, None, points[row], body)
            rows[row] = self.jacobian[2]
        np.negative(rows, out=rows)
        h = lowest[near] - clearance[near]
        if self.relaxed:
            h = np.maximum(h, 0.0)
        return mink.Constraint(G=rows, h=h)


class SupportCandidates:
    """The lowest of a body's support points along a direction that turns slowly, exactly, from
    the few points that can be lowest near the direction of the last full scan.

    A body's hull has up to thousands of points, and the IK asks for the lowest one several times a
    frame, each time along nearly the same body-frame direction. Tilting the direction by d (a
    vector) moves each point's height by (p - c) . d plus a part shared by all points (c: the
    points' centroid), so by at most spread * |d| relative to the others (spread: the largest
    |p - c|). A point more than 2 * spread * reuse above the lowest of the last scan cannot be the
    lowest while |d| <= reuse; past that the next query scans every point again.
    """

    def __init__(self, points: np.ndarray, radii: np.ndarray, reuse: float) -> None:
        self.points = points
        self.radii = radii
        self.reuse_squared = reuse**2
        centred = points - points.mean(axis=0)
        self.band = 2.0 * float(np.linalg.norm(centred, axis=1).max()) * reuse
        self.scanned_along = np.full(3, np.inf)
        self.subset = np.arange(len(points))
        self.subset_points = points
        self.subset_radii = radii

    def lowest(self, origin_z: float, up: np.ndarray) -> tuple[int, float]:
        """Index and world z (radius included) of the lowest support point of a body whose origin is
        at `origin_z` and whose frame sees the world's up axis as the unit vector `up`; the same as
        a scan of every point, ties to the lowest index."""
        turn = up - self.scanned_along
        if turn @ turn > self.reuse_squared:
            self._scan(up)
        z = origin_z + self.subset_points @ up - self.subset_radii
        best = z.argmin()
        return int(self.subset[best]), float(z[best])

    def _scan(self, up: np.ndarray) -> None:
        heights = self.points @ up - self.radii
        # The margin over the band absorbs rounding: a point at the band's edge is kept.
        self.subset = np.flatnonzero(heights <= heights.min() + self.band + 1e-9)
        self.subset_points = self.points[self.subset]
        self.subset_radii = self.radii[self.subset]
        self.scanned_along = up.copy()
