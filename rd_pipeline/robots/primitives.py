"""Primitive shapes fitted to a robot's collision meshes, for a fast training model.

Every collision mesh becomes the smaller of two shapes that contain all of its vertices: a capsule
along its principal axis, or a box on the axes of its body (links are drawn square to their frames,
and a box tilted to a lopsided mesh's principal axes would reach into a neighbour on one side only). A foot
mesh becomes the box of its extent in the foot frame, so the sole keeps a flat face (four corner
contacts) on the floor. Shapes are in the frame of the body that owns them.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import mujoco
import numpy as np


@dataclass(frozen=True)
class FittedShape:
    """One primitive standing in for one collision mesh geom."""

    geom: int
    """The mesh geom it replaces (id in the compiled model)."""
    kind: str
    """`capsule` or `box`."""
    pos: np.ndarray
    """(3,) centre in the body frame."""
    quat: np.ndarray
    """(4,) wxyz orientation in the body frame (a capsule's axis is its local z)."""
    size: np.ndarray
    """MuJoCo size: capsule (radius, half length, 0), box (3 half extents)."""
    vertices: np.ndarray
    """(V, 3) the mesh's vertices in the body frame (what the shape must contain)."""

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """(V,) distance of body-frame points to the shape's surface, negative inside."""
        local = _to_local(points, self.pos, self.quat)
        if self.kind == "capsule":
            half = self.size[1]
            nearest = np.clip(local[:, 2], -half, half)
            axis_point = np.stack([np.zeros_like(nearest), np.zeros_like(nearest), nearest], axis=1)
            return np.linalg.norm(local - axis_point, axis=1) - self.size[0]
        outside = np.abs(local) - self.size
        return np.linalg.norm(np.maximum(outside, 0.0), axis=1) + np.minimum(outside.max(axis=1), 0.0)

    def volume(self) -> float:
        if self.kind == "capsule":
            radius = self.size[0]
            return float(np.pi * radius**2 * 2 * self.size[1] + 4.0 / 3.0 * np.pi * radius**3)
        return float(np.prod(2 * self.size))


def mesh_vertices_in_body(model: mujoco.MjModel, geom: int) -> np.ndarray:
    """(V, 3) vertices of mesh geom `geom`, in the frame of its body."""
    mesh = model.geom_dataid[geom]
    start = model.mesh_vertadr[mesh]
    vertices = model.mesh_vert[start : start + model.mesh_vertnum[mesh]]
    rotation = np.empty(9)
    mujoco.mju_quat2Mat(rotation, model.geom_quat[geom])
    return vertices @ rotation.reshape(3, 3).T + model.geom_pos[geom]


def covering_capsule(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pos, quat, size) of a capsule along the points' principal axis that contains every point.

    The radius is the largest distance from the axis; each end of the segment is pulled in as far
    as the points near that end allow (a point at axial t and distance d needs the segment to reach
    t -+ sqrt(r^2 - d^2)), so the caps hug the ends.
    """
    centre = points.mean(axis=0)
    axis = principal_axes(points)[0]
    along = (points - centre) @ axis
    across = np.linalg.norm((points - centre) - along[:, None] * axis, axis=1)
    radius = float(across.max())
    reach = np.sqrt(np.maximum(radius**2 - across**2, 0.0))
    low = float((along + reach).min())
    high = float((along - reach).max())
    if low > high:  # short and wide: the caps alone contain everything
        low = high = 0.5 * (low + high)
    mid = centre + 0.5 * (low + high) * axis
    return mid, _quat_z_to(axis), np.array([radius, 0.5 * (high - low), 0.0])


def covering_box(points: np.ndarray, axes: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pos, quat, size) of the box around the points with edges along `axes` (rows; default the
    body frame's)."""
    axes = np.eye(3) if axes is None else axes
    if np.linalg.det(axes) < 0:
        axes = axes * np.array([[1.0], [1.0], [-1.0]])
    local = points @ axes.T
    low = local.min(axis=0)
    high = local.max(axis=0)
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, axes.T.flatten())
    return 0.5 * (low + high) @ axes, quat, 0.5 * (high - low)


def principal_axes(points: np.ndarray) -> np.ndarray:
    """(3, 3) the points' principal axes as rows, largest spread first."""
    _, _, axes = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)
    return axes


def fit_collision_meshes(
    model: mujoco.MjModel, foot_bodies: tuple[int, ...], max_pieces: int = 3, volume_ratio: float = 1.6
) -> list[FittedShape]:
    """Primitives for every colliding mesh geom of `model`: one box on each of `foot_bodies`;
    elsewhere the mesh cut into 1..`max_pieces` slabs along its principal axis, each slab the
    smaller of its covering capsule and box, with the fewest slabs whose total volume is within
    `volume_ratio` of the mesh's convex hull (a torso wide at the shoulders and narrow at the
    waist needs two, or its box would swallow the elbows)."""
    shapes = []
    for geom in range(model.ngeom):
        colliding = model.geom_contype[geom] or model.geom_conaffinity[geom]
        if model.geom_type[geom] != mujoco.mjtGeom.mjGEOM_MESH or not colliding:
            continue
        vertices = mesh_vertices_in_body(model, geom)
        faces = _mesh_faces(model, geom)
        if model.geom_bodyid[geom] in foot_bodies:
            shapes.append(FittedShape(geom, "box", *covering_box(vertices), vertices))
            continue
        hull = _hull_volume(vertices)
        best: list[FittedShape] = []
        for pieces in range(1, max_pieces + 1):
            fitted = [_smallest_cover(geom, slab) for slab in _slabs(vertices, faces, pieces)]
            if not best or sum(f.volume() for f in fitted) < sum(f.volume() for f in best):
                best = fitted
            if sum(f.volume() for f in best) <= volume_ratio * hull:
                break
        shapes.extend(best)
    return shapes


def _smallest_cover(geom: int, points: np.ndarray) -> FittedShape:
    capsule = FittedShape(geom, "capsule", *covering_capsule(points), points)
    box = FittedShape(geom, "box", *covering_box(points), points)
    return min(capsule, box, key=FittedShape.volume)


def _slabs(points: np.ndarray, faces: np.ndarray, pieces: int) -> list[np.ndarray]:
    """The mesh cut into `pieces` equal-length slabs along its principal axis: each slab's
    vertices plus the points where mesh edges cross its boundary planes, so the slabs' covers
    leave no gap in the surface."""
    along = (points - points.mean(axis=0)) @ principal_axes(points)[0]
    cuts = np.linspace(along.min(), along.max(), pieces + 1)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    a = along[edges[:, 0]]
    b = along[edges[:, 1]]
    slabs = []
    for lo, hi in itertools.pairwise(cuts):
        members = [points[(along >= lo) & (along <= hi)]]
        for plane in (lo, hi):
            crossing = (np.minimum(a, b) < plane) & (np.maximum(a, b) > plane)
            t = (plane - a[crossing]) / (b[crossing] - a[crossing])
            start = points[edges[crossing, 0]]
            members.append(start + t[:, None] * (points[edges[crossing, 1]] - start))
        slab = np.concatenate(members)
        if len(slab) >= 4:
            slabs.append(slab)
    return slabs


def _mesh_faces(model: mujoco.MjModel, geom: int) -> np.ndarray:
    """(F, 3) vertex indices of the triangles of mesh geom `geom`."""
    mesh = model.geom_dataid[geom]
    start = model.mesh_faceadr[mesh]
    return model.mesh_face[start : start + model.mesh_facenum[mesh]]


def _hull_volume(points: np.ndarray) -> float:
    from scipy.spatial import ConvexHull

    return float(ConvexHull(points).volume)


def _quat_z_to(axis: np.ndarray) -> np.ndarray:
    """wxyz rotation taking +z to `axis`."""
    quat = np.empty(4)
    mujoco.mju_quatZ2Vec(quat, axis)
    return quat


def _to_local(points: np.ndarray, pos: np.ndarray, quat: np.ndarray) -> np.ndarray:
    rotation = np.empty(9)
    mujoco.mju_quat2Mat(rotation, quat)
    return (points - pos) @ rotation.reshape(3, 3)
