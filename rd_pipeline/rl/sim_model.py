"""The simulation model of a robot: collision geometry only, a floor, and PD inside the physics loop.

The MJCF's torque motors become MuJoCo position actuators with the given kp and kd and a force
range of the effort limit, so the PD torque is computed and clipped at every 500 Hz physics step
by MuJoCo itself; a policy sets the 50 Hz targets as `ctrl`. Training builds it from the robot
config, a deploy loop from `policy.json` alone.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np

from rd_pipeline.robots import Robot
from rd_pipeline.robots.assets import asset_path


def pd_simulation_model(mjcf: Path, joint_names: Sequence[str], kp: np.ndarray, kd: np.ndarray,
                        effort_limit: np.ndarray, timestep: float) -> mujoco.MjModel:
    """A compiled model whose actuator driving `joint_names[i]` is a PD with `kp[i]`, `kd[i]`, `effort_limit[i]`."""
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
    return spec.compile()


def simulation_model(robot: Robot, timestep: float = 0.002) -> mujoco.MjModel:
    """The training model: the robot config's gains and effort limits."""
    config = robot.config
    return pd_simulation_model(asset_path(config.mjcf), config.joint_names, config.kp, config.kd,
                               config.effort_limit, timestep)


RANDOMIZED_FIELDS = ("body_mass", "geom_friction", "body_ipos", "actuator_gainprm", "actuator_biasprm")
"""Model fields `randomized_copy` changes (per-world arrays in batched backends)."""


def randomized_copy(model: mujoco.MjModel, mass: float, friction: float, kp: float, kd: float,
                    com_body: int | None = None, com_offset: np.ndarray | None = None) -> mujoco.MjModel:
    """A copy of `model` with link masses, ground friction and PD gains scaled by the given factors
    and, optionally, body `com_body`'s centre of mass moved by `com_offset` (domain randomization)."""
    out = copy.copy(model)
    out.body_mass[1:] *= mass
    out.geom_friction[:, 0] *= friction
    if com_body is not None:
        out.body_ipos[com_body] += com_offset
    out.actuator_gainprm[:, 0] *= kp
    out.actuator_biasprm[:, 1] *= kp
    out.actuator_biasprm[:, 2] *= kd
    return out
