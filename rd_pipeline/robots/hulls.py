"""Each body's collision geometry as points with radii, for lowest-point queries against the floor.

A geom's lowest world point along any direction is one of a few support points grown by a radius:
a sphere's centre, a capsule's two end centres (radius r), a box's corners, a cylinder's rim, a
mesh's convex-hull vertices (radius 0). The floor ruler and the IK ground limit share this.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import mujoco
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from rd_pipeline.errors import PipelineError
from rd_pipeline.robots import Robot
from rd_pipeline.robots.model import collision_geoms

_RIM_POINTS = 24
"""Points per cylinder rim: the lowest rim point is found within r * (1 - cos(pi / 24)) = 0.9% of r."""


@dataclass(frozen=True)
class BodyHulls:
    """Support points of every body's collision geoms (and the feet's visual meshes), in the body frame."""

    body_names: tuple[str, ...]
    """Bodies with collision geometry, in model order."""
    body_ids: np.ndarray
    """(N,) MuJoCo body id of each."""
    points: tuple[np.ndarray, ...]
    """Per body, (V, 3) support points in the body frame."""
    radii: tuple[np.ndarray, ...]
    """Per body, (V,) radius grown around each point."""

    @classmethod
    def from_robot(cls, robot: Robot) -> BodyHulls:
        model = robot.model
        feet = {robot.body_ids[b] for b in robot.config.foot_bodies}
        names, ids, points, radii = [], [], [], []
        for body in range(1, model.nbody):
            geoms = collision_geoms(model, body)
            if body in feet:
                # The G1 feet collide through sole spheres; the foot mesh around them is what a
                # viewer sees on the floor, so it must not sink either.
                meshes = [g for g in _body_geoms(model, body) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH]
                geoms = sorted({*geoms, *meshes})
            if not geoms:
                continue
            support = [_geom_support(model, g) for g in geoms]
            names.append(model.body(body).name)
            ids.append(body)
            points.append(np.concatenate([p for p, _ in support]))
            radii.append(np.concatenate([r for _, r in support]))
        return cls(tuple(names), np.array(ids), tuple(points), tuple(radii))

    def without(self, bodies: tuple[str, ...]) -> BodyHulls:
        """The hulls of every body but `bodies`."""
        keep = [k for k, name in enumerate(self.body_names) if name not in bodies]
        return BodyHulls(
            tuple(self.body_names[k] for k in keep),
            self.body_ids[keep],
            tuple(self.points[k] for k in keep),
            tuple(self.radii[k] for k in keep),
        )

    @cached_property
    def reach(self) -> np.ndarray:
        """(N,) how far each body's geometry reaches from its origin, radius included: a body whose
        origin is higher above the floor than this cannot touch it."""
        return np.array([np.max(np.linalg.norm(p, axis=1) + r) for p, r in zip(self.points, self.radii)])

    @cached_property
    def boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """Per body, the centre (N, 3) and half extents (N, 3) of the box in its frame that holds
        every support point grown by its radius."""
        low = np.array([(p - r[:, None]).min(axis=0) for p, r in zip(self.points, self.radii)])
        high = np.array([(p + r[:, None]).max(axis=0) for p, r in zip(self.points, self.radii)])
        return (low + high) / 2.0, (high - low) / 2.0

    def lowest_bound(self, origin_z: np.ndarray, z_rows: np.ndarray) -> np.ndarray:
        """(..., N) a lower bound of each body's lowest world z, from its origin's height (..., N) and
        the world z of its axes (..., N, 3): the lowest corner of its box, or its reach below the
        origin, whichever is higher. Exact support points are never below it."""
        centre, half = self.boxes
        box = (z_rows * centre).sum(axis=-1) - (np.abs(z_rows) * half).sum(axis=-1)
        return origin_z + np.maximum(box, -self.reach)

    def sink_depth(self, body_pos_w: np.ndarray, body_quat_w: np.ndarray, body_names: Sequence[str]) -> np.ndarray:
        """(T,) how far the deepest body reaches below the floor (0 where none does), from body poses
        (T, B, 3), (T, B, 4 wxyz): `lowest_z`'s minimum clipped at 0."""
        return self.deepest_below_floor(body_pos_w, body_quat_w, body_names)[0]

    def deepest_below_floor(
        self,
        body_pos_w: np.ndarray,
        body_quat_w: np.ndarray,
        body_names: Sequence[str],
    ) -> tuple[np.ndarray, np.ndarray]:
        """(T,) `sink_depth`, and (T,) the index into `body_names` of this class of the deepest body
        (-1 where none is below; the first of equals, as an argmax over `lowest_z`).

        Each body's points are only looked at in the frames where its `lowest_bound` is below the
        floor: on a whole take most bodies are far above it in most frames."""
        columns = [list(body_names).index(body) for body in self.body_names]
        pos = body_pos_w[:, columns]
        quat = body_quat_w[:, columns]
        bound = self.lowest_bound(pos[..., 2], _rotation_z_row(quat))
        depth = np.zeros(body_pos_w.shape[0])
        deepest = np.full(body_pos_w.shape[0], -1)
        for k, (points, radii) in enumerate(zip(self.points, self.radii)):
            near = np.flatnonzero(bound[:, k] < 0.0)
            if near.size == 0:
                continue
            sunk = -support_lowest_z(pos[near, k], quat[near, k], points, radii)
            deeper = sunk > depth[near]
            depth[near[deeper]] = sunk[deeper]
            deepest[near[deeper]] = k
        return depth, deepest

    def lowest_z(self, body_pos_w: np.ndarray, body_quat_w: np.ndarray, body_names: Sequence[str]) -> np.ndarray:
        """(T, N) lowest world z of each body's collision geometry from body poses (T, B, 3), (T, B, 4 wxyz)."""
        index = {name: i for i, name in enumerate(body_names)}
        lowest = np.empty((body_pos_w.shape[0], len(self.body_names)))
        for k, (body, points, radii) in enumerate(zip(self.body_names, self.points, self.radii)):
            i = index[body]
            lowest[:, k] = support_lowest_z(body_pos_w[:, i], body_quat_w[:, i], points, radii)
        return lowest


def support_lowest_z(
    pos_w: np.ndarray,
    quat_w: np.ndarray,
    points: np.ndarray,
    radii: np.ndarray | float,
) -> np.ndarray:
    """(T,) lowest world z of one body's support points (V, 3), grown by `radii`, at poses (T, 3), (T, 4 wxyz).

    Only world z is needed, so only the third row of each rotation matrix.
    """
    return pos_w[:, 2] + (_rotation_z_row(quat_w) @ points.T - radii).min(axis=1)


def _rotation_z_row(quat_wxyz: np.ndarray) -> np.ndarray:
    """(T, 3) third row of the rotation matrix of unit quaternions (T, 4 wxyz): world z of body axes."""
    quat = quat_wxyz / np.linalg.norm(quat_wxyz, axis=-1, keepdims=True)
    w = quat[..., 0]
    x = quat[..., 1]
    y = quat[..., 2]
    z = quat[..., 3]
    return np.stack([2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)], axis=-1)


def mesh_points_in_body(model: mujoco.MjModel, geom: int) -> np.ndarray:
    """(V, 3) vertices of a mesh geom in its body frame (MuJoCo recentres meshes on the geom frame)."""
    mesh = model.geom_dataid[geom]
    start = model.mesh_vertadr[mesh]
    count = model.mesh_vertnum[mesh]
    vertices = model.mesh_vert[start : start + count].astype(float)
    return _to_body(model, geom, vertices)


_MESH_HULLS: weakref.WeakKeyDictionary[mujoco.MjModel, dict[tuple[int, ...], np.ndarray]] = weakref.WeakKeyDictionary()
"""Per model, the hulls `mesh_hull_in_body` made, by geoms; dropped with the model."""


def mesh_hull_in_body(model: mujoco.MjModel, geoms: tuple[int, ...]) -> np.ndarray:
    """(V, 3) hull vertices of the mesh geoms `geoms` together, in their body's frame; computed once
    per model: a retarget asks for the same hulls in its IK and in its floor and skate rulers, and
    G1's took a third of a second each time."""
    known = _MESH_HULLS.setdefault(model, {})
    if geoms not in known:
        points = np.concatenate([mesh_points_in_body(model, g) for g in geoms])
        hull = hull_vertices(points)
        hull.flags.writeable = False  # shared by every caller
        known[geoms] = hull
    return known[geoms]


def hull_vertices(points: np.ndarray) -> np.ndarray:
    """The extreme point along any direction is a hull vertex, so the hull is all a lowest-point query needs."""
    try:
        return points[ConvexHull(points).vertices]
    except QhullError:  # flat or degenerate meshes: keep every point
        return points


def _geom_support(model: mujoco.MjModel, geom: int) -> tuple[np.ndarray, np.ndarray]:
    kind = model.geom_type[geom]
    size = model.geom_size[geom]
    if kind == mujoco.mjtGeom.mjGEOM_MESH:
        vertices = mesh_hull_in_body(model, (geom,))
        return vertices, np.zeros(len(vertices))
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return _to_body(model, geom, np.zeros((1, 3))), np.array([size[0]])
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        ends = np.array([[0.0, 0.0, -size[1]], [0.0, 0.0, size[1]]])
        return _to_body(model, geom, ends), np.full(2, size[0])
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * size
        return _to_body(model, geom, corners), np.zeros(8)
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        angle = np.linspace(0.0, 2.0 * np.pi, _RIM_POINTS, endpoint=False)
        rim = size[0] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
        points = np.concatenate([np.column_stack([rim, np.full(_RIM_POINTS, z)]) for z in (-size[1], size[1])])
        return _to_body(model, geom, points), np.zeros(len(points))
    name = model.geom(geom).name or f"#{geom}"
    body = model.body(model.geom_bodyid[geom]).name
    shape = mujoco.mjtGeom(kind).name
    raise PipelineError(
        f"robot model: collision geom {name} of body '{body}' is a {shape}, which the floor ruler cannot measure"
    )


def _body_geoms(model: mujoco.MjModel, body: int) -> list[int]:
    return [g for g in range(model.ngeom) if model.geom_bodyid[g] == body]


def _to_body(model: mujoco.MjModel, geom: int, points: np.ndarray) -> np.ndarray:
    rotation = np.empty(9)
    mujoco.mju_quat2Mat(rotation, model.geom_quat[geom])
    return points @ rotation.reshape(3, 3).T + model.geom_pos[geom]
