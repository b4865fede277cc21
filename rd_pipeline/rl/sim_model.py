"""The simulation model of a robot: collision geometry only, a floor, and PD inside the physics loop.

The MJCF's torque motors become MuJoCo position actuators with the config's kp and kd and a force
range of the effort limit, so the PD torque is computed and clipped at every 500 Hz physics step
by MuJoCo itself; the policy sets the 50 Hz targets as `ctrl`.
"""

from __future__ import annotations

import mujoco
import numpy as np

from rd_pipeline.robots import Robot
from rd_pipeline.robots.assets import asset_path


def simulation_model(robot: Robot, timestep: float = 0.002, kp_scale: np.ndarray | None = None,
                     kd_scale: np.ndarray | None = None) -> mujoco.MjModel:
    """A compiled model for simulation; `kp_scale`/`kd_scale` (J,) randomize the PD gains."""
    config = robot.config
    spec = mujoco.MjSpec.from_file(str(asset_path(config.mjcf)))
    spec.discard_visual()
    spec.option.timestep = timestep
    # The PD damping acts on light distal links (wrists, ankles); integrating it implicitly keeps
    # the 500 Hz loop stable without inventing armature values the models do not have.
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    if not any(g.type == mujoco.mjtGeom.mjGEOM_PLANE for g in spec.geoms):  # some MJCFs bring their own floor
        spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05])
    kp = config.kp * (1.0 if kp_scale is None else kp_scale)
    kd = config.kd * (1.0 if kd_scale is None else kd_scale)
    by_joint = {name: i for i, name in enumerate(config.joint_names)}
    for actuator in spec.actuators:
        i = by_joint[actuator.target]
        actuator.set_to_position(kp=float(kp[i]), kv=float(kd[i]))
        actuator.ctrllimited = False
        actuator.forcelimited = True
        actuator.forcerange = [-float(config.effort_limit[i]), float(config.effort_limit[i])]
    return spec.compile()
