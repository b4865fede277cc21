"""Robot models in MuJoCo (MJCF) and Pinocchio (URDF), checked against the robot config."""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass
from functools import lru_cache

import mujoco
import numpy as np

from rd_pipeline.errors import PipelineError
from rd_pipeline.robots.assets import robot_file
from rd_pipeline.robots.config import RobotConfig, load_robot_config


@dataclass(frozen=True)
class Robot:
    """A robot config with its MuJoCo model and the index maps the pipeline uses."""

    config: RobotConfig
    """The validated config."""
    model: mujoco.MjModel
    """MuJoCo model compiled from the MJCF."""
    qpos_indices: np.ndarray
    """qpos address of each joint in `config.joint_names`."""
    dof_indices: np.ndarray
    """qvel address of each joint in `config.joint_names`."""
    body_ids: dict[str, int]
    """Body name -> MuJoCo body id, for every body but the world."""

    @property
    def body_names(self) -> list[str]:
        return list(self.body_ids)

    @property
    def joint_range(self) -> np.ndarray:
        """(J, 2) position limits from the model, in config joint order."""
        joint_ids = [self.model.joint(name).id for name in self.config.joint_names]
        return self.model.jnt_range[joint_ids].copy()

    @property
    def retarget_range(self) -> np.ndarray:
        """(J, 2) the bounds retargeting keeps each joint within: the model's range, narrowed where
        the config's `retarget_range` says."""
        return _intersect(self.joint_range, self.config.retarget_range)


def _intersect(ranges: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """(J, 2) each row of `ranges` narrowed by the same row of `bounds`."""
    return np.stack([np.maximum(ranges[:, 0], bounds[:, 0]), np.minimum(ranges[:, 1], bounds[:, 1])], axis=1)


def load_robot(name: str) -> Robot:
    """Load and validate a robot; every mismatch between config and model is one clear error."""
    return _load_robot_cached(name)


@lru_cache(maxsize=8)
def _load_robot_cached(name: str) -> Robot:
    config = load_robot_config(name)
    path = robot_file(config, "mjcf")
    try:
        model = mujoco.MjModel.from_xml_path(str(path))
    except ValueError as exc:
        raise PipelineError(f"{path}: MuJoCo could not load the model ({str(exc).splitlines()[0]})") from None
    check_against_model(config, model)
    qpos = np.array([model.jnt_qposadr[model.joint(j).id] for j in config.joint_names])
    dofs = np.array([model.jnt_dofadr[model.joint(j).id] for j in config.joint_names])
    bodies = {model.body(i).name: i for i in range(1, model.nbody)}
    return Robot(config=config, model=model, qpos_indices=qpos, dof_indices=dofs, body_ids=bodies)


def check_against_model(config: RobotConfig, model: mujoco.MjModel) -> None:
    """Every named joint and body exists and `joints.order` is the actuator order."""
    where = config.source
    joints = [model.joint(i).name for i in range(model.njnt)]
    bodies = [model.body(i).name for i in range(model.nbody)]
    if model.jnt_type[0] != mujoco.mjtJoint.mjJNT_FREE:
        raise PipelineError(f"{where}: the model's first joint is not a free joint (floating base)")
    for joint in config.joint_names:
        if joint not in joints:
            raise PipelineError(f"{where}: joint '{joint}' is not in the model{_did_you_mean(joint, joints)}")
    actuated = [model.joint(model.actuator_trnid[a, 0]).name for a in range(model.nu)]
    if len(actuated) != len(config.joint_names):
        raise PipelineError(
            f"{where}: joints.order has {len(config.joint_names)} joints but the model has {len(actuated)} actuators"
        )
    for i, (ours, theirs) in enumerate(zip(config.joint_names, actuated)):
        if ours != theirs:
            raise PipelineError(f"{where}: joints.order[{i}] is '{ours}' but actuator {i} drives '{theirs}'")
    named_bodies = {
        "bodies.root": [config.root_body],
        "bodies.feet": list(config.foot_bodies),
        "bodies.tracking": list(config.tracking_bodies),
        "bodies.termination": list(config.termination_bodies),
        "bodies.retarget": list(config.retarget_map),
        "collision.pairs": [body for pair in config.collision_pairs for body in pair],
    }
    for field, names in named_bodies.items():
        for body in names:
            if body not in bodies:
                raise PipelineError(
                    f"{where}: {field} names body '{body}', which is not in the model{_did_you_mean(body, bodies)}"
                )
    _check_retarget_range(config, model)


def _check_retarget_range(config: RobotConfig, model: mujoco.MjModel) -> None:
    """The range retargeting may use keeps the default pose: the solve starts from it."""
    model_ranges = np.array([model.joint(joint).range for joint in config.joint_names])
    usable = _intersect(model_ranges, config.retarget_range)
    for joint, (lower, upper), default in zip(config.joint_names, usable, config.default_pos):
        if not lower <= default <= upper:
            raise PipelineError(
                f"{config.source}: joints.retarget_range leaves '{joint}' [{lower:g}, {upper:g}] within the model's"
                f" range, which does not hold its default_pos {default:g}"
            )


def _did_you_mean(name: str, options: list[str]) -> str:
    close = difflib.get_close_matches(name, options, n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""


def load_pinocchio_model(config: RobotConfig):
    """Pinocchio model from the URDF with a free-flyer root (kinematics only, no meshes needed)."""
    import pinocchio as pin

    path = robot_file(config, "urdf")
    text = path.read_text()
    # h1_2_handless.urdf has anonymous <material> tags that urdfdom rejects; name them in memory.
    counter = iter(range(10**6))
    text = re.sub(r"<material>", lambda _: f'<material name="rd_material_{next(counter)}">', text)
    return pin.buildModelFromXML(text, pin.JointModelFreeFlyer())


def collision_geoms(model: mujoco.MjModel, body_id: int) -> list[int]:
    """The body's collision geoms (contype or conaffinity set), else all its geoms (the H1-2 wrists are visual only)."""
    geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == body_id]
    colliding = [g for g in geoms if model.geom_contype[g] or model.geom_conaffinity[g]]
    return colliding or geoms


def collision_geom_pairs(robot: Robot) -> np.ndarray:
    """(P, 2) geom pairs of the config's `collision_pairs` (every collision geom of one body against the other's)."""
    model = robot.model
    pairs = [
        (first, second)
        for body_a, body_b in robot.config.collision_pairs
        for first in collision_geoms(model, robot.body_ids[body_a])
        for second in collision_geoms(model, robot.body_ids[body_b])
    ]
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def leg_joints(robot: Robot, feet: tuple[str, ...] | None = None) -> list[str]:
    """Config joints on the chains from the root body to `feet` (default: both feet), in config order."""
    model = robot.model
    on_chain: set[str] = set()
    for foot in robot.config.foot_bodies if feet is None else feet:
        body = robot.body_ids[foot]
        while body > 0:
            for joint in range(model.body_jntadr[body], model.body_jntadr[body] + model.body_jntnum[body]):
                on_chain.add(model.joint(joint).name)
            body = model.body_parentid[body]
    return [j for j in robot.config.joint_names if j in on_chain]
