"""From a human motion to the robot's IK targets: per-limb scaling, frames, contacts, planted feet.

Everything here is computed from the human skeleton and the robot model; nothing is tuned per clip.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import mujoco
import numpy as np
from scipy.interpolate import interp1d
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation, Slerp

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.contact import ContactThresholds, label_contacts
from rd_pipeline.motion.human import HumanMotion
from rd_pipeline.retarget.body_contact import hold_in_contact, label_body_contacts
from rd_pipeline.retarget.config import BodyContactConfig, TargetShaping
from rd_pipeline.retarget.feet import SoleFrames, leg_yaw_range, plant_foot
from rd_pipeline.retarget.frames import frame_from_axes, yaw_and_pitch
from rd_pipeline.retarget.lafan_joints import FEET, HIPS_LR, KNEES, LOWER_SPINE, PELVIS, SHOULDERS_LR, TOES, TORSO
from rd_pipeline.retarget.legs import keep_feet_apart, keep_legs_reachable, match_stance_width
from rd_pipeline.robots import Robot

TARGETS_FILE = "targets.npz"
"""File name of the keypoint targets inside a retarget artifact."""


@dataclass(frozen=True)
class RetargetTargets:
    """Per-frame targets for the robot's key bodies at the output rate."""

    fps: float
    """Frame rate of the targets (the reference-motion rate)."""
    bodies: tuple[str, ...]
    """Robot bodies with a position target, in `positions` order."""
    human_joints: tuple[str, ...]
    """The human joint each body follows."""
    positions: np.ndarray
    """(T, K, 3) target positions (scaled human; feet planted while in contact)."""
    orientations: dict[str, np.ndarray]
    """Body -> (T, 3, 3) target orientations (pelvis, torso, feet)."""
    foot_contact: np.ndarray
    """(T, 2) left/right foot planted, from the human feet."""
    foot_lift: np.ndarray
    """(T, 2) height the left/right sole target clears the floor by (0 planted, the swing clearance mid-swing)."""
    swing_clearance_m: float
    """The clearance a swinging sole target rises to before it travels."""
    body_contact: np.ndarray
    """(T, K) which key bodies (other than the feet) rest on the floor, from the human joints."""
    human_scale: float
    """Global human-to-robot scale (leg-length ratio) applied to the root."""
    human_pelvis: np.ndarray
    """(T, 3) the human hips scaled by `human_scale`, before any shaping (the pelvis height ruler)."""
    human_standing: np.ndarray
    """(T,) the human stands (`TargetShaping.standing_hips_fraction`): the frames the feet's soles are learnt on."""

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    def frames(self, span: slice) -> RetargetTargets:
        """The targets of the frames `span` alone, as a clip of their own."""
        return replace(
            self,
            positions=self.positions[span],
            orientations={body: rotations[span] for body, rotations in self.orientations.items()},
            foot_contact=self.foot_contact[span],
            foot_lift=self.foot_lift[span],
            body_contact=self.body_contact[span],
            human_pelvis=self.human_pelvis[span],
            human_standing=self.human_standing[span],
        )

    def foot_orientations(self, feet: tuple[str, str]) -> np.ndarray:
        """(T, 2, 3, 3) target orientations of the left and right foot bodies."""
        return np.stack([self.orientations[foot] for foot in feet], axis=1)

    def save(self, path) -> None:
        """Keypoint targets for viewing beside the robot (the orientations are not needed there)."""
        np.savez(
            path,
            fps=self.fps,
            bodies=np.array(self.bodies),
            human_joints=np.array(self.human_joints),
            positions=self.positions,
            foot_contact=self.foot_contact,
            body_contact=self.body_contact,
            human_pelvis=self.human_pelvis,
        )


def resample_human(human: HumanMotion, fps: float) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Joint positions (T', J, 3) and rotation matrices (T', J, 3, 3) at `fps`, same duration as the source."""
    n_source = human.n_frames
    n_target = int(round(n_source * fps / human.fps))
    if n_source < 2 or n_target < 2:
        raise PipelineError(
            f"clip of {n_source} frame(s) ({human.duration_s:.4f} s) is too short: retargeting needs two frames at {fps:g} Hz"
        )
    source_t = np.arange(n_source) / human.fps
    target_t = np.minimum(np.arange(n_target) / fps, source_t[-1])
    positions = interp1d(source_t, human.pos_w, kind="cubic" if n_source > 3 else "linear", axis=0)(target_t)
    rotations = np.empty((n_target, len(human.names), 3, 3))
    for j in range(len(human.names)):
        source = Rotation.from_quat(human.quat_w[:, j][:, [1, 2, 3, 0]])
        rotations[:, j] = Slerp(source_t, source)(target_t).as_matrix()
    return positions, rotations, list(human.names)


def robot_rest_positions(robot: Robot, bodies: list[str]) -> np.ndarray:
    """(K, 3) body positions with every joint at zero (Unitree frames are world-aligned there)."""
    data = mujoco.MjData(robot.model)
    data.qpos[3] = 1.0
    mujoco.mj_kinematics(robot.model, data)
    return np.array([data.xpos[robot.body_ids[b]] for b in bodies])


def robot_rest_rotation(robot: Robot, body: str) -> np.ndarray:
    data = mujoco.MjData(robot.model)
    data.qpos[3] = 1.0
    mujoco.mj_kinematics(robot.model, data)
    return data.xmat[robot.body_ids[body]].reshape(3, 3).copy()


_LEG = ((HIPS_LR[0], KNEES[0]), (KNEES[0], FEET[0]))
"""The left leg, hip to knee to ankle: the length robot and human are scaled by."""


@dataclass(frozen=True)
class _Clip:
    """The resampled human and the robot it is mapped onto: what the shaping steps read."""

    pos: np.ndarray
    """(T, J, 3) human joint positions at the output rate (smoothed)."""
    rot: np.ndarray
    """(T, J, 3, 3) human joint rotations at the output rate."""
    index: dict[str, int]
    """Human joint -> its index in `pos` and `rot`."""
    fps: float
    robot: Robot
    body_for: dict[str, str]
    """Human joint -> the robot body that follows it."""
    rest: dict[str, np.ndarray]
    """Human joint -> (3,) its robot body's position in the rest pose."""
    root_scale: float
    """Human-to-robot scale of the root path (the leg-length ratio)."""
    standing: np.ndarray
    """(T,) the human stands: hips above a fraction of the leg length (`TargetShaping.standing_hips_fraction`)."""

    def human(self, joint: str) -> np.ndarray:
        """(T, 3) the human joint's path."""
        return self.pos[:, self.index[joint]]


def build_targets(
    human: HumanMotion,
    robot: Robot,
    fps: float,
    foot_vertices: tuple[np.ndarray, np.ndarray],
    contact: ContactThresholds,
    shape: TargetShaping = TargetShaping(),
    body_contact: BodyContactConfig = BodyContactConfig(),
) -> RetargetTargets:
    """The robot's key-body targets at `fps`: the human limb chain at the robot's proportions,
    legs kept apart and reachable, feet planted on their soles (`foot_vertices`, left and right)
    and bodies resting on the floor held there."""
    config = robot.config
    body_for = _body_for_joint(robot, human)
    human_pos, human_rot, names = resample_human(human, fps)
    if shape.smoothing_s > 0:
        human_pos = gaussian_filter1d(human_pos, shape.smoothing_s * fps, axis=0, mode="nearest")
    index = {name: i for i, name in enumerate(names)}
    joints = list(config.retarget_map.values())
    bodies = list(config.retarget_map.keys())
    rest = dict(zip(joints, robot_rest_positions(robot, bodies)))
    root_scale = _root_scale(human_pos, index, rest)
    standing = _standing(human_pos, index, shape.standing_hips_fraction)
    clip = _Clip(human_pos, human_rot, index, fps, robot, body_for, rest, root_scale, standing)
    orientations = _orientations(human_pos, index, robot, body_for, rest)
    targets = _limb_chain(clip, human, joints, orientations)
    _spread_feet(targets, rest, orientations[body_for[PELVIS]], fps, shape)
    foot_contact = _human_contacts(human_pos, index, fps, contact)
    _stand_on_soles(targets, foot_contact, foot_vertices)
    foot_lift = _plant_feet(clip, targets, orientations, foot_contact, foot_vertices, shape)
    keep_legs_reachable(targets, rest, fps, shape.reach_fraction, shape.leg_correction_smoothing_s)
    touching = label_body_contacts(human_pos, index, joints, fps, body_contact)
    resting = _hold_resting_bodies(targets, joints, touching, human_pos * root_scale, index, fps, body_contact)
    return RetargetTargets(
        fps=fps,
        bodies=tuple(bodies),
        human_joints=tuple(joints),
        positions=np.stack([targets[j] for j in joints], axis=1),
        orientations=orientations,
        foot_contact=foot_contact,
        foot_lift=foot_lift,
        swing_clearance_m=shape.swing_clearance_m,
        body_contact=resting,
        human_scale=root_scale,
        human_pelvis=human_pos[:, index[PELVIS]] * root_scale,
        human_standing=standing,
    )


def _body_for_joint(robot: Robot, human: HumanMotion) -> dict[str, str]:
    """Human joint -> robot body, from the robot's retarget map, checked against what the
    targets need and what the skeleton has."""
    config = robot.config
    body_for = {human_joint: body for body, human_joint in config.retarget_map.items()}
    for needed in (PELVIS, TORSO, *FEET, *KNEES, *HIPS_LR, *SHOULDERS_LR):
        if needed not in body_for:
            raise PipelineError(f"{config.source}: bodies.retarget must map a body to LAFAN1 joint '{needed}'")
    for human_joint, foot in zip(FEET, config.foot_bodies):
        if body_for[human_joint] != foot:
            raise PipelineError(
                f"{config.source}: bodies.retarget maps '{body_for[human_joint]}' to '{human_joint}', "
                f"but bodies.feet names '{foot}'"
            )
    missing = [j for j in config.retarget_map.values() if j not in human.names]
    if missing:
        raise PipelineError(f"{config.source}: bodies.retarget names human joint '{missing[0]}', not in the skeleton")
    unread = [j for j in (*TOES, LOWER_SPINE) if j not in human.names]
    if unread:
        raise PipelineError(f"the skeleton has no joint '{unread[0]}', which retargeting reads (a LAFAN1 skeleton has)")
    return body_for


def _root_scale(pos: np.ndarray, index: dict[str, int], rest: dict[str, np.ndarray]) -> float:
    """Robot over human leg length (hip to knee to ankle, left side): the scale of the root path."""
    leg_robot = sum(np.linalg.norm(rest[a] - rest[b]) for a, b in _LEG)
    return float(leg_robot / _human_leg_length(pos, index))


def _human_leg_length(pos: np.ndarray, index: dict[str, int]) -> float:
    """Hip to knee to ankle, left side, median over the clip (bone lengths do not change)."""
    return sum(_median_length(pos, index, a, b) for a, b in _LEG)


def _standing(pos: np.ndarray, index: dict[str, int], hips_fraction: float) -> np.ndarray:
    """(T,) the human stands: hips higher than `hips_fraction` of the leg length. Measured
    against the skeleton, not the clip, so a clip that opens on the floor reads the same."""
    hips = pos[:, index[PELVIS], 2]
    return hips > hips_fraction * _human_leg_length(pos, index)


def _limb_chain(
    clip: _Clip,
    human: HumanMotion,
    joints: list[str],
    orientations: dict[str, np.ndarray],
) -> dict[str, np.ndarray]:
    """Human joint -> (T, 3) target, down the chain from the scaled pelvis.

    Keypoints on the same rigid part as their parent (hips on the pelvis, torso and shoulders on
    the torso) keep the robot's own offset, turned by the parent's target orientation; limbs
    (knees, feet, elbows, hands) follow the human direction with the robot's segment length.
    """
    rest = clip.rest
    parent_of = {joint: _mapped_ancestor(human, joint, set(joints)) for joint in joints}
    rigid_frame = {PELVIS: orientations[clip.body_for[PELVIS]], TORSO: orientations[clip.body_for[TORSO]]}
    rest_rotation = {joint: robot_rest_rotation(clip.robot, clip.body_for[joint]) for joint in rigid_frame}
    targets: dict[str, np.ndarray] = {PELVIS: clip.human(PELVIS) * clip.root_scale}
    for joint in _topological(parent_of):
        parent = parent_of[joint]
        if parent is None:
            continue
        if parent in rigid_frame:
            offset_in_parent = rest_rotation[parent].T @ (rest[joint] - rest[parent])
            targets[joint] = targets[parent] + rigid_frame[parent] @ offset_in_parent
        else:
            segment = clip.human(joint) - clip.human(parent)
            scale = np.linalg.norm(rest[joint] - rest[parent]) / _median_length(clip.pos, clip.index, joint, parent)
            targets[joint] = targets[parent] + scale * segment
    return targets


def _spread_feet(
    targets: dict[str, np.ndarray],
    rest: dict[str, np.ndarray],
    pelvis_frame: np.ndarray,
    fps: float,
    shape: TargetShaping,
) -> None:
    """The robot's stance width, and feet never closer than its fraction of it (in place)."""
    match_stance_width(targets, rest, pelvis_frame)
    keep_feet_apart(
        targets,
        rest,
        pelvis_frame,
        fps,
        shape.min_stance_fraction,
        shape.leg_correction_smoothing_s,
        shape.feet_line_smoothing_s,
    )


def _stand_on_soles(
    targets: dict[str, np.ndarray],
    foot_contact: np.ndarray,
    foot_vertices: tuple[np.ndarray, np.ndarray],
) -> None:
    """Lift or lower every target (in place) so planted feet sit at the robot's sole height:
    robot and human ankles are not at the same height in proportion to the legs."""
    sole_height = np.array([-vertices[:, 2].min() for vertices in foot_vertices])
    foot_z = np.stack([targets[f][:, 2] for f in FEET], axis=1)
    planted = foot_z[foot_contact] if foot_contact.any() else foot_z.min(axis=1)
    shift = float(np.median(sole_height)) - float(np.median(planted))
    for joint in targets:
        targets[joint] = targets[joint] + np.array([0.0, 0.0, shift])


def _plant_feet(
    clip: _Clip,
    targets: dict[str, np.ndarray],
    orientations: dict[str, np.ndarray],
    foot_contact: np.ndarray,
    foot_vertices: tuple[np.ndarray, np.ndarray],
    shape: TargetShaping,
) -> np.ndarray:
    """Both feet through `plant_foot`: their targets, orientations and (T, 2) contact labels are
    replaced in place. Returns the (T, 2) height each sole target clears the floor by.

    A foot with no trusted plant to learn its sole on borrows the other foot's lesson."""
    pelvis_yaw = np.unwrap(yaw_and_pitch(orientations[clip.body_for[PELVIS]][:, :, 0])[0])
    contact = foot_contact.copy()
    trusted = [SoleFrames((clip.standing, _upright(clip, side, shape))) for side in range(2)]
    planned = [
        _plant_one(clip, targets, contact, foot_vertices, pelvis_yaw, side, trusted[side], shape) for side in range(2)
    ]
    lessons = [plan[-1] for plan in planned]
    for side in range(2):
        borrowed = lessons[1 - side]
        if lessons[side] is None and borrowed is not None:
            sole = SoleFrames(trusted[side].trusted, borrowed)
            planned[side] = _plant_one(clip, targets, contact, foot_vertices, pelvis_yaw, side, sole, shape)
    foot_lift = np.zeros((clip.pos.shape[0], 2))
    for side, foot in enumerate(FEET):
        position, rotation, foot_lift[:, side], foot_contact[:, side], _ = planned[side]
        targets[foot] = position
        offset = robot_rest_rotation(clip.robot, clip.body_for[foot])
        orientations[clip.body_for[foot]] = rotation @ offset
    return foot_lift


def _plant_one(
    clip: _Clip,
    targets: dict[str, np.ndarray],
    contact: np.ndarray,
    foot_vertices: tuple[np.ndarray, np.ndarray],
    pelvis_yaw: np.ndarray,
    side: int,
    sole: SoleFrames,
    shape: TargetShaping,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Rotation | None]:
    """`plant_foot` on one side, from the labels and targets the chain gave it."""
    foot = FEET[side]
    toe = TOES[side]
    return plant_foot(
        targets[foot],
        clip.human(toe) - clip.human(foot),
        clip.rot[:, clip.index[foot]],
        contact[:, side],
        foot_vertices[side],
        clip.fps,
        pelvis_yaw,
        leg_yaw_range(clip.robot, clip.body_for[foot]),
        0.5 * (clip.human(foot) + clip.human(toe)) * clip.root_scale,
        sole,
        shape,
    )


def _upright(clip: _Clip, side: int, shape: TargetShaping) -> np.ndarray:
    """(T,) the side's knee is higher above its ankle than `upright_shin_fraction` of the shin."""
    shin = clip.human(KNEES[side]) - clip.human(FEET[side])
    length = float(np.median(np.linalg.norm(shin, axis=-1)))
    return shin[:, 2] > shape.upright_shin_fraction * length


def _hold_resting_bodies(
    targets: dict[str, np.ndarray],
    joints: list[str],
    touching: np.ndarray,
    human_pos: np.ndarray,
    index: dict[str, int],
    fps: float,
    settings: BodyContactConfig,
) -> np.ndarray:
    """Hold the target of each key body (in place) while it rests on the floor; (T, K) the frames
    each is held (a body that slides along the floor touches it but does not rest)."""
    resting = np.zeros_like(touching)
    for k, joint in enumerate(joints):
        if touching[:, k].any():
            human = human_pos[:, index[joint]]
            targets[joint], resting[:, k] = hold_in_contact(targets[joint], touching[:, k], human, fps, settings)
    return resting


def _mapped_ancestor(human: HumanMotion, joint: str, mapped: set[str]) -> str | None:
    parent = int(human.parents[human.names.index(joint)])
    while parent >= 0:
        if human.names[parent] in mapped:
            return human.names[parent]
        parent = int(human.parents[parent])
    return None


def _topological(parent_of: dict[str, str | None]) -> list[str]:
    ordered: list[str] = []
    while len(ordered) < len(parent_of):
        for joint, parent in parent_of.items():
            if joint not in ordered and (parent is None or parent in ordered):
                ordered.append(joint)
    return ordered


def _median_length(pos: np.ndarray, index: dict[str, int], a: str, b: str) -> float:
    return float(np.median(np.linalg.norm(pos[:, index[a]] - pos[:, index[b]], axis=-1)))


def _human_contacts(pos: np.ndarray, index: dict[str, int], fps: float, thresholds: ContactThresholds) -> np.ndarray:
    """Foot contact from the lower of ankle and toe, each relative to its own planted height."""
    heights = []
    points = []
    planted = thresholds.ground_percentile
    for foot, toe in zip(FEET, TOES):
        ankle_z = pos[:, index[foot], 2]
        toe_z = pos[:, index[toe], 2]
        heights.append(np.minimum(ankle_z - np.percentile(ankle_z, planted), toe_z - np.percentile(toe_z, planted)))
        points.append(0.5 * (pos[:, index[foot]] + pos[:, index[toe]]))
    foot_points = np.stack(points, axis=1)
    foot_points[..., 2] = np.stack(heights, axis=1)
    return label_contacts(foot_points, fps, 0.0, thresholds)


def _orientations(
    pos: np.ndarray,
    index: dict[str, int],
    robot: Robot,
    body_for: dict[str, str],
    rest: dict[str, np.ndarray],
) -> dict[str, np.ndarray]:
    """Pelvis and torso frames from keypoints, times the robot's rest offset for the same construction."""

    def pelvis_frame(p):  # up along the spine, left across the hips
        return frame_from_axes(p[TORSO] - p[PELVIS], p[HIPS_LR[0]] - p[HIPS_LR[1]])

    def torso_frame(p):  # up from the lower spine to the shoulders, left across the shoulders
        shoulders = 0.5 * (p[SHOULDERS_LR[0]] + p[SHOULDERS_LR[1]])
        return frame_from_axes(shoulders - p[LOWER_SPINE], p[SHOULDERS_LR[0]] - p[SHOULDERS_LR[1]])

    human = {name: pos[:, i] for name, i in index.items()}
    # The robot's rest frames use the same construction; robots have no lower-spine body, so the
    # pelvis stands in for it, and the pelvis "up" is vertical by definition of the rest pose (some
    # torso bodies sit right at the pelvis origin).
    robot_rest = {**rest, LOWER_SPINE: rest[PELVIS], TORSO: rest[PELVIS] + np.array([0.0, 0.0, 1.0])}
    out = {}
    for joint, frame in ((PELVIS, pelvis_frame), (TORSO, torso_frame)):
        body = body_for[joint]
        offset = frame(robot_rest).T @ robot_rest_rotation(robot, body)
        out[body] = frame(human) @ offset
    return out
