"""Robot configuration: one TOML file per robot under `robots/`, parsed into a frozen dataclass.

Per-joint values (gains, limits, default pose) are written as glob patterns over joint names, the
first matching pattern winning, so a config reads like the robot's spec sheet rather than a list
of 27 numbers.
"""

from __future__ import annotations

import fnmatch
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rd_pipeline import paths
from rd_pipeline.errors import PipelineError, nearest
from rd_pipeline.paths import ROBOT_CONFIG_DIR


@dataclass(frozen=True)
class RobotConfig:
    """Everything the pipeline needs to know about one robot, in the MJCF actuator order."""

    name: str
    """Short id used on the command line and in artifact paths (`g1`, `h1`, `h1_2`)."""
    description: str
    """One line for `rd-pipeline robots`."""
    source: Path
    """The TOML file this came from (named in every error message)."""
    mjcf: str
    """MJCF path relative to the unitree_ros `robots/` folder."""
    urdf: str
    """URDF path relative to the unitree_ros `robots/` folder."""
    joint_names: tuple[str, ...]
    """All actuated joints, in the model's actuator order."""
    policy_joints: tuple[str, ...]
    """Joints the policy commands; the rest are held at `default_pos` by PD."""
    residual_indices: tuple[int, ...]
    """Indices into `policy_joints` that receive residual actions in `selective` mode."""
    kp: np.ndarray
    """PD stiffness per joint (N m/rad)."""
    kd: np.ndarray
    """PD damping per joint (N m s/rad)."""
    effort_limit: np.ndarray
    """Torque limit per joint (N m)."""
    velocity_limit: np.ndarray
    """Velocity limit per joint (rad/s)."""
    default_pos: np.ndarray
    """Default standing pose per joint (rad)."""
    retarget_range: np.ndarray
    """(J, 2) bounds per joint (rad) that retargeting keeps within, intersected with the model's
    range; (-inf, inf) where the TOML's `joints.retarget_range` names none. For a model range wider
    than any performer's joint, where the IK could fold a limb onto an alias of its pose."""
    root_body: str
    """The floating-base body."""
    foot_bodies: tuple[str, str]
    """Left and right foot bodies (contact labels, foot metrics)."""
    tracking_bodies: tuple[str, ...]
    """Bodies tracked by rewards and validation metrics."""
    keypoint_bodies: tuple[str, ...]
    """The "VR keypoints" the keypoint rewards track, among `tracking_bodies`: the torso and the
    hands (the forearms' ends on a robot without hands)."""
    termination_bodies: tuple[str, ...]
    """Bodies whose distance from the reference ends an episode ("motion far")."""
    retarget_map: dict[str, str]
    """Robot body -> LAFAN1 joint it follows during retargeting."""
    csv_joints: tuple[str, ...]
    """Joint order of the LAFAN1_Retargeting_Dataset CSV columns for this robot."""
    collision_pairs: tuple[tuple[str, str], ...]
    """Body pairs that must not touch (arms vs torso, leg vs leg): kept apart by retargeting, counted by metrics."""

    @property
    def policy_indices(self) -> np.ndarray:
        """Positions of the policy joints within `joint_names`."""
        return np.array([self.joint_names.index(j) for j in self.policy_joints], dtype=np.int64)


def _config_dirs() -> list[Path]:
    """Where robot TOMLs are looked for: the user's folder (if any) first, then `robots/`."""
    user = paths.robot_configs_dir()
    return [user, ROBOT_CONFIG_DIR] if user is not None else [ROBOT_CONFIG_DIR]


def config_path(name: str) -> Path:
    """The TOML of robot `name`: the user's folder first, then the shipped configs."""
    for folder in _config_dirs():
        if (folder / f"{name}.toml").is_file():
            return folder / f"{name}.toml"
    return ROBOT_CONFIG_DIR / f"{name}.toml"


def available_robots() -> list[str]:
    return sorted({path.stem for folder in _config_dirs() for path in folder.glob("*.toml")})


def load_robot_config(name: str, path: Path | None = None) -> RobotConfig:
    """Parse `robots/<name>.toml` (or `path`). Checks against the model are in `robots.model`."""
    path = path or config_path(name)
    if not path.is_file():
        raise PipelineError(f"unknown robot '{name}': no {path} (available: {', '.join(available_robots())})")
    try:
        raw = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise PipelineError(f"{path}: {exc}") from None
    _check_layout(raw, path)
    reader = _Fields(raw, path)
    joints = reader.names("joints.order")
    policy_joints = reader.names("joints.policy", everything="all", whole=joints)
    csv_joints = reader.names("dataset.csv_joints", everything="order", whole=joints)
    feet = reader.names("bodies.feet")
    if len(feet) != 2:
        raise PipelineError(f"{path}: bodies.feet must name 2 bodies (left, right), got {len(feet)}")
    config = RobotConfig(
        name=reader.get("name", str),
        description=reader.get("description", str),
        source=path,
        mjcf=reader.get("asset.mjcf", str),
        urdf=reader.get("asset.urdf", str),
        joint_names=joints,
        policy_joints=policy_joints,
        residual_indices=reader.indices("joints.residual_indices"),
        kp=reader.per_joint("joints.kp", joints, "positive"),
        kd=reader.per_joint("joints.kd", joints, "non-negative"),
        effort_limit=reader.per_joint("joints.effort_limit", joints, "positive"),
        velocity_limit=reader.per_joint("joints.velocity_limit", joints, "positive"),
        default_pos=reader.per_joint("joints.default_pos", joints),
        retarget_range=reader.joint_bounds("joints.retarget_range", joints),
        root_body=reader.get("bodies.root", str),
        foot_bodies=(feet[0], feet[1]),
        tracking_bodies=reader.names("bodies.tracking"),
        keypoint_bodies=reader.names("bodies.keypoints"),
        termination_bodies=reader.names("bodies.termination"),
        retarget_map=dict(reader.get("bodies.retarget", dict)),
        csv_joints=csv_joints,
        collision_pairs=reader.pairs("collision.pairs"),
    )
    if config.name != name:
        raise PipelineError(f"{path}: name is '{config.name}' but the file is for robot '{name}'")
    _check_internal(config)
    return config


LAYOUT: dict[str, tuple[str, ...]] = {
    "": ("name", "description", "asset", "joints", "bodies", "collision", "dataset"),
    "asset": ("mjcf", "urdf"),
    "joints": (
        "order",
        "policy",
        "residual_indices",
        "kp",
        "kd",
        "effort_limit",
        "velocity_limit",
        "default_pos",
        "retarget_range",
    ),
    "bodies": ("root", "feet", "tracking", "keypoints", "termination", "retarget"),
    "collision": ("pairs",),
    "dataset": ("csv_joints",),
}
"""The tables of a robot TOML and the keys each holds (below them, joint patterns and body names)."""


def _check_layout(raw: dict, path: Path) -> None:
    """Refuse a key or table a robot TOML does not have (a misspelt one would be ignored)."""
    for table, keys in LAYOUT.items():
        node = raw.get(table, {}) if table else raw
        if not isinstance(node, dict):
            continue  # a table given as a value: the typed reading names it
        where = f"in [{table}]" if table else "at the top"
        for key in node:
            if key not in keys:
                hint = nearest(key, keys)
                raise PipelineError(f"{path}: unknown key '{key}' {where}{hint} (keys: {', '.join(keys)})")


def _check_internal(config: RobotConfig) -> None:
    where = config.source
    # The rewards find these by their place among the tracked bodies.
    roles = {
        "bodies.root": (config.root_body,),
        "bodies.feet": config.foot_bodies,
        "bodies.keypoints": config.keypoint_bodies,
        "bodies.termination": config.termination_bodies,
    }
    for field, bodies in roles.items():
        for body in bodies:
            if body not in config.tracking_bodies:
                raise PipelineError(f"{where}: {field} names '{body}', which is not in bodies.tracking")
    for joint in config.policy_joints:
        if joint not in config.joint_names:
            raise PipelineError(f"{where}: joints.policy names '{joint}', which is not in joints.order")
    for index in config.residual_indices:
        if not 0 <= index < len(config.policy_joints):
            raise PipelineError(
                f"{where}: joints.residual_indices has {index}, outside the {len(config.policy_joints)} policy joints"
            )


class _Fields:
    """Typed access to dotted TOML keys with errors that name the file and the key."""

    def __init__(self, raw: dict, path: Path) -> None:
        self.raw = raw
        self.path = path

    def get(self, dotted: str, kind: type | tuple[type, ...]):
        node = self._find(dotted)
        if node is None:
            raise PipelineError(f"{self.path}: missing field '{dotted}'")
        if not isinstance(node, kind):
            raise PipelineError(f"{self.path}: field '{dotted}' has the wrong type ({type(node).__name__})")
        return node

    def names(self, dotted: str, everything: str | None = None, whole: tuple[str, ...] = ()) -> tuple[str, ...]:
        """A list of names, or the word `everything` (such as "all") for the `whole` list."""
        node = self.get(dotted, (list, str) if everything else list)
        if everything is not None and node == everything:
            return whole
        if isinstance(node, str) or not all(isinstance(name, str) for name in node):
            wanted = f'"{everything}" or a list of names' if everything else "a list of names"
            raise PipelineError(f"{self.path}: {dotted} must be {wanted}, got {node!r}")
        return tuple(node)

    def indices(self, dotted: str) -> tuple[int, ...]:
        """A list of whole numbers (TOML's true is not one)."""
        node = self.get(dotted, list)
        for value in node:
            if not isinstance(value, int) or isinstance(value, bool):
                raise PipelineError(f"{self.path}: {dotted} must be a list of whole numbers, got {value!r} in it")
        return tuple(node)

    def pairs(self, dotted: str) -> tuple[tuple[str, str], ...]:
        """A list of [name, name] pairs."""
        out = []
        for pair in self.get(dotted, list):
            if not isinstance(pair, list) or len(pair) != 2 or not all(isinstance(name, str) for name in pair):
                raise PipelineError(f"{self.path}: {dotted} must hold pairs of two body names, got {pair!r}")
            out.append((pair[0], pair[1]))
        return tuple(out)

    def per_joint(self, dotted: str, joints: tuple[str, ...], sign: str | None = None) -> np.ndarray:
        """Per joint, the value of the first pattern that matches it; `sign` ("positive",
        "non-negative") where a gain or a limit of the other sign means nothing."""
        patterns: dict = self.get(dotted, dict)
        values = np.empty(len(joints))
        for i, joint in enumerate(joints):
            match = next((p for p in patterns if fnmatch.fnmatchcase(joint, p)), None)
            if match is None:
                raise PipelineError(f"{self.path}: {dotted} has no pattern matching joint '{joint}'")
            value = patterns[match]
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not np.isfinite(value):
                raise PipelineError(f'{self.path}: {dotted}."{match}" must be a finite number, got {value!r}')
            if (sign == "positive" and value <= 0) or (sign == "non-negative" and value < 0):
                raise PipelineError(f'{self.path}: {dotted}."{match}" must be {sign}, got {value!r}')
            values[i] = float(value)
        values.setflags(write=False)
        return values

    def joint_bounds(self, dotted: str, joints: tuple[str, ...]) -> np.ndarray:
        """(J, 2) [lower, upper] per joint from an optional pattern table; unbounded where none matches."""
        patterns: dict = self.get(dotted, dict) if self._find(dotted) is not None else {}
        bounds = np.tile([-np.inf, np.inf], (len(joints), 1))
        for i, joint in enumerate(joints):
            match = next((p for p in patterns if fnmatch.fnmatchcase(joint, p)), None)
            if match is None:
                continue
            value = patterns[match]
            numbers = isinstance(value, list) and all(isinstance(v, (int, float)) for v in value)
            if not numbers or len(value) != 2 or not value[0] < value[1]:
                raise PipelineError(
                    f'{self.path}: {dotted}."{match}" must be [lower, upper] with lower < upper, got {value!r}'
                )
            bounds[i] = value
        bounds.setflags(write=False)
        return bounds

    def _find(self, dotted: str):
        """The value at a dotted key, or None where the TOML has none (TOML has no null)."""
        node = self.raw
        for part in dotted.split("."):
            if not isinstance(node, dict) or part not in node:
                return None
            node = node[part]
        return node
