"""The simulation model of a robot: collision geometry only, a floor, and PD inside the physics loop.

The MJCF's torque motors become MuJoCo position actuators with the given kp and kd and a force
range of the effort limit, so the PD torque is computed and clipped at every 500 Hz physics step
by MuJoCo itself; a policy sets the 50 Hz targets as `ctrl`. Training builds it from the robot
config, a deploy loop from `policy.json` alone.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from rd_pipeline.env.config import CollisionModel
from rd_pipeline.robots import Robot
from rd_pipeline.robots.assets import robot_file
from rd_pipeline.robots.primitives import fit_collision_meshes


def pd_simulation_model(
    mjcf: Path, joint_names: Sequence[str], kp: np.ndarray, kd: np.ndarray, effort_limit: np.ndarray, timestep: float
) -> mujoco.MjModel:
    """A compiled model whose actuator driving `joint_names[i]` is a PD with `kp[i]`, `kd[i]`, `effort_limit[i]`."""
    return _pd_spec(mjcf, joint_names, kp, kd, effort_limit, timestep).compile()


def simulation_model(
    robot: Robot,
    timestep: float = 0.002,
    collision: CollisionModel = "mesh",
    body_sensors: bool = False,
    solver: SolverBudget | None = None,
) -> mujoco.MjModel:
    """The robot with the config's gains and effort limits: `mesh` collides the MJCF's geometry
    (every pair of geoms), `primitive` the fitted training shapes (see `primitive_collision`).
    `body_sensors` adds the sensors a batched rollout reads its results from (`add_body_sensors`);
    `solver` caps the constraint solver's work (None: MuJoCo's defaults)."""
    config = robot.config
    spec = _pd_spec(robot_file(config, "mjcf"), config.joint_names, config.kp, config.kd, config.effort_limit, timestep)
    if solver is not None:
        spec.option.iterations = solver.iterations
        spec.option.ls_iterations = solver.ls_iterations
    if collision == "primitive":
        primitive_collision(spec, config.foot_bodies, config.collision_pairs)
    if body_sensors:
        add_body_sensors(spec)
    return spec.compile()


@dataclass(frozen=True)
class SolverBudget:
    """How much work MuJoCo's constraint solver may do per physics step."""

    iterations: int
    """Solver iterations."""
    ls_iterations: int
    """Line-search iterations per solver iteration."""


BODY_SENSORS = ("pos", "quat", "linvel", "angvel", "contact_force")
"""Per robot body, in this order: world position (3), orientation wxyz (4), world linear and
angular velocity of the body origin (3 + 3), net contact force on the body, world frame (3)."""


def add_body_sensors(spec: mujoco.MjSpec) -> None:
    """Sensors for every body but the world (`BODY_SENSORS`), then each actuator's force."""
    frame = (
        mujoco.mjtSensor.mjSENS_FRAMEPOS,
        mujoco.mjtSensor.mjSENS_FRAMEQUAT,
        mujoco.mjtSensor.mjSENS_FRAMELINVEL,
        mujoco.mjtSensor.mjSENS_FRAMEANGVEL,
    )
    # Contact sensor: data = force (bit 1), reduce = net force (3), one result, in the world frame.
    net_force = [1 << int(mujoco.mjtConDataField.mjCONDATA_FORCE), 3, 1]
    for body in spec.bodies[1:]:
        for name, kind in zip(BODY_SENSORS, frame):
            spec.add_sensor(
                name=f"rd_{name}_{body.name}", type=kind, objtype=mujoco.mjtObj.mjOBJ_XBODY, objname=body.name
            )
        spec.add_sensor(
            name=f"rd_contact_force_{body.name}",
            type=mujoco.mjtSensor.mjSENS_CONTACT,
            objtype=mujoco.mjtObj.mjOBJ_BODY,
            objname=body.name,
            intprm=net_force,
        )
    for actuator in spec.actuators:
        actuator.name = actuator.name or f"rd_{actuator.target}"
        spec.add_sensor(
            name=f"rd_actuator_force_{actuator.name}",
            type=mujoco.mjtSensor.mjSENS_ACTUATORFRC,
            objtype=mujoco.mjtObj.mjOBJ_ACTUATOR,
            objname=actuator.name,
        )


def body_sensor_index(model: mujoco.MjModel, name: str) -> np.ndarray:
    """(nbody - 1, dim) sensordata indices of body sensor `name` (one of `BODY_SENSORS`), body 1 on."""
    rows = []
    for body in range(1, model.nbody):
        sensor = model.sensor(f"rd_{name}_{model.body(body).name}")
        rows.append(sensor.adr[0] + np.arange(sensor.dim[0]))
    return np.array(rows)


def actuator_force_index(model: mujoco.MjModel) -> np.ndarray:
    """(nu,) sensordata indices of the actuator forces."""
    return np.array([model.sensor(f"rd_actuator_force_{model.actuator(i).name}").adr[0] for i in range(model.nu)])


def primitive_collision(
    spec: mujoco.MjSpec, foot_bodies: Sequence[str], collision_pairs: Sequence[tuple[str, str]]
) -> None:
    """Turn `spec` into a training model: every collision mesh becomes its fitted primitives (see
    `rd_pipeline.robots.primitives`); robot geoms touch the floor, and each other only in the robot
    config's collision pairs (frictionless, condim 1), as mjlab trains its humanoids."""
    for i, geom in enumerate(spec.geoms):
        geom.name = geom.name or f"rd_geom_{i}"
    model = spec.compile()
    feet = tuple(model.body(name).id for name in foot_bodies)
    by_name = {geom.name: geom for geom in spec.geoms}
    pieces: dict[int, int] = {}
    for shape in fit_collision_meshes(model, feet):
        mesh_geom = by_name[model.geom(shape.geom).name]
        count = pieces.get(shape.geom, 0)
        pieces[shape.geom] = count + 1
        if count == 0:
            geom = mesh_geom
        else:  # a further slab of the same mesh: a new geom with the mesh geom's contact settings
            body = spec.body(model.body(int(model.geom_bodyid[shape.geom])).name)
            geom = body.add_geom(
                name=f"{mesh_geom.name}_{count}",
                friction=mesh_geom.friction,
                condim=mesh_geom.condim,
                solref=mesh_geom.solref,
                solimp=mesh_geom.solimp,
                margin=mesh_geom.margin,
                gap=mesh_geom.gap,
                priority=mesh_geom.priority,
            )
        geom.type = mujoco.mjtGeom.mjGEOM_CAPSULE if shape.kind == "capsule" else mujoco.mjtGeom.mjGEOM_BOX
        geom.meshname = ""
        geom.pos = shape.pos
        geom.quat = shape.quat
        geom.size = shape.size
    # No geom uses a mesh any more; without them a model is kilobytes instead of ~60 MB (G1), and
    # training keeps one model per environment.
    for mesh in list(spec.meshes):
        spec.delete(mesh)
    # Robot geoms collide with the floor, and with each other only in the config's pairs: every
    # other body pair is excluded, so the broadphase drops it before any narrowphase test.
    # condim 1 makes self-contacts frictionless; floor contacts take the floor's condim 3.
    model = spec.compile()
    for geom in spec.geoms:
        if int(model.geom(geom.name).bodyid[0]) != 0:
            geom.condim = 1
    wanted = {frozenset(pair) for pair in collision_pairs}
    bodies = [model.body(i).name for i in range(1, model.nbody)]
    for i, first in enumerate(bodies):
        for second in bodies[i + 1 :]:
            if frozenset((first, second)) not in wanted:
                spec.add_exclude(bodyname1=first, bodyname2=second)


def _pd_spec(
    mjcf: Path, joint_names: Sequence[str], kp: np.ndarray, kd: np.ndarray, effort_limit: np.ndarray, timestep: float
) -> mujoco.MjSpec:
    spec = mujoco.MjSpec.from_file(str(mjcf))
    spec.discard_visual()
    spec.option.timestep = timestep
    # The PD damping acts on light distal links (wrists, ankles); integrating it implicitly keeps
    # the 500 Hz loop stable without inventing armature values the models do not have.
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    if not any(g.type == mujoco.mjtGeom.mjGEOM_PLANE for g in spec.geoms):  # some MJCFs bring their own floor
        spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05])
    by_joint = {name: i for i, name in enumerate(joint_names)}
    for actuator in spec.actuators:
        i = by_joint[actuator.target]
        actuator.set_to_position(kp=float(kp[i]), kv=float(kd[i]))
        actuator.ctrllimited = False
        actuator.forcelimited = True
        actuator.forcerange = [-float(effort_limit[i]), float(effort_limit[i])]
    return spec


RANDOMIZED_FIELDS = (
    "body_mass",
    "body_inertia",
    "geom_friction",
    "body_ipos",
    "actuator_gainprm",
    "actuator_biasprm",
)
"""Model fields `randomized_copy` changes (per-world arrays in batched backends)."""


def randomized_copy(
    model: mujoco.MjModel,
    mass: float,
    friction: float,
    kp: float,
    kd: float,
    com_body: int | None = None,
    com_offset: np.ndarray | None = None,
) -> mujoco.MjModel:
    """A copy of `model` with link masses (and with them their rotational inertias: the same shape,
    heavier), ground friction and PD gains scaled by the given factors and, optionally, body
    `com_body`'s centre of mass moved by `com_offset` (domain randomization)."""
    out = copy.copy(model)
    out.body_mass[1:] *= mass
    out.body_inertia[1:] *= mass
    out.geom_friction[:, 0] *= friction
    if com_body is not None:
        out.body_ipos[com_body] += com_offset
    out.actuator_gainprm[:, 0] *= kp
    out.actuator_biasprm[:, 1] *= kp
    out.actuator_biasprm[:, 2] *= kd
    return out
