"""The training collision model: primitives fitted to every collision mesh, floor and config pairs only."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import trimesh

from rd_pipeline.env.sim_model import simulation_model
from rd_pipeline.robots import load_robot
from rd_pipeline.robots.config import available_robots
from rd_pipeline.robots.primitives import fit_collision_meshes, mesh_vertices_in_body

COVER_TOLERANCE_M = 1e-6
"""Every point of a mesh's surface lies inside one of its primitives (up to rounding)."""
MAX_VOLUME_RATIO = 2.0
"""A mesh's primitives together are at most this many times its convex hull's volume (measured: 1.81 at worst)."""


def _model(name: str) -> tuple[mujoco.MjModel, tuple[str, ...]]:
    """The robot's mesh model, the one the primitives are fitted to."""
    robot = load_robot(name)
    return simulation_model(robot, collision="mesh"), robot.config.foot_bodies


def _surface_points(model: mujoco.MjModel, geom: int, rng: np.random.Generator) -> np.ndarray:
    """Vertices plus random points on every triangle of mesh geom `geom`, in its body frame."""
    vertices = mesh_vertices_in_body(model, geom)
    mesh = model.geom_dataid[geom]
    faces = model.mesh_face[model.mesh_faceadr[mesh] : model.mesh_faceadr[mesh] + model.mesh_facenum[mesh]]
    weights = rng.dirichlet(np.ones(3), size=len(faces))
    return np.concatenate([vertices, np.einsum("fk,fkd->fd", weights, vertices[faces])])


@pytest.mark.parametrize("name", available_robots())
def test_fitted_primitives_cover_each_collision_mesh(name: str) -> None:
    model, foot_bodies = _model(name)
    meshes = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH]
    shapes = fit_collision_meshes(model, tuple(model.body(b).id for b in foot_bodies))
    assert sorted({shape.geom for shape in shapes}) == meshes  # every collision mesh is replaced
    rng = np.random.default_rng(0)
    for geom in meshes:
        body = model.body(int(model.geom_bodyid[geom])).name
        own = [shape for shape in shapes if shape.geom == geom]
        points = _surface_points(model, geom, rng)
        inside = np.min([shape.signed_distance(points) for shape in own], axis=0)
        assert inside.max() <= COVER_TOLERANCE_M, body
        hull = trimesh.convex.convex_hull(mesh_vertices_in_body(model, geom))
        assert sum(shape.volume() for shape in own) <= MAX_VOLUME_RATIO * hull.volume, body
        if body in foot_bodies:
            assert [shape.kind for shape in own] == ["box"]  # one flat sole on the floor


def test_a_primitive_that_misses_part_of_its_mesh_is_seen() -> None:
    model, _ = _model("g1")
    shape = fit_collision_meshes(model, ())[0]
    raised = shape.vertices + np.array([0.0, 0.0, 0.02]) * (shape.vertices[:, 2:] > shape.vertices[:, 2].mean())
    assert shape.signed_distance(raised).max() > 0.005


@pytest.mark.parametrize("name", available_robots())
def test_primitive_model_collides_with_the_floor_and_only_in_config_pairs(name: str) -> None:
    robot = load_robot(name)
    model = simulation_model(robot, collision="primitive")
    assert not any(model.geom_type == mujoco.mjtGeom.mjGEOM_MESH)
    data = mujoco.MjData(model)
    joints = [model.jnt_qposadr[model.joint(j).id] for j in robot.config.joint_names]
    body_of = lambda geom: model.body(int(model.geom_bodyid[geom])).name
    configured = {frozenset(pair) for pair in robot.config.collision_pairs}
    rng = np.random.default_rng(0)
    seen = set()
    for _ in range(300):  # random poses in the air: self-contacts only in the configured pairs, frictionless
        data.qpos[:] = model.qpos0
        data.qpos[2] = 2.0
        low, high = robot.joint_range.T
        data.qpos[joints] = rng.uniform(low, high)
        mujoco.mj_forward(model, data)
        for contact in data.contact[: data.ncon]:
            pair = frozenset((body_of(contact.geom1), body_of(contact.geom2)))
            assert pair in configured, sorted(pair)
            assert contact.dim == 1
            seen.add(pair)
    assert len(seen) >= 2
    # Dropped onto the floor at the default pose, the robot stands on its soles.
    data.qpos[:] = model.qpos0
    data.qpos[joints] = robot.config.default_pos
    data.qpos[2] = 2.0
    mujoco.mj_forward(model, data)
    feet = {robot.body_ids[f] for f in robot.config.foot_bodies}
    floor = next(g for g in range(model.ngeom) if model.geom_bodyid[g] == 0)
    soles = [g for g in range(model.ngeom) if model.geom_bodyid[g] in feet]
    data.qpos[2] -= min(mujoco.mj_geomDistance(model, data, floor, g, 3.0, None) for g in soles) - 0.005
    touching = set()
    for _ in range(25):
        mujoco.mj_step(model, data)
        touching |= {int(model.geom_bodyid[g]) for c in data.contact[: data.ncon] for g in (c.geom1, c.geom2)}
    assert touching - {0} == feet
    assert all(c.dim == 3 for c in data.contact[: data.ncon])  # floor contacts keep their friction
