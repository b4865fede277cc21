"""Retargeting quality of a reference motion: whole-body floor penetration, pelvis height, stance skating,
limits, self-collision, smoothness, keypoint error and divergence.

One ruler for every source of reference motions (the LAFAN1_Retargeting_Dataset CSVs, our own retargeting) so
their numbers can share a table. Heights are measured against the world plane z = 0 with no per-clip ground
estimate: a clip whose feet sink below the floor is scored for it, which is the point of the metric.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.robots import Robot
from rd_pipeline.robots.hulls import BodyHulls, mesh_hull_in_body, support_lowest_z
from rd_pipeline.robots.model import collision_geom_pairs

QUALITY_FILE = "quality.json"
"""File name of a quality report inside an artifact (retarget and import stages)."""
QUALITY_SERIES_FILE = "quality_frames.npz"
"""File name of the per-frame rulers (`quality_series`) inside an artifact, plotted by `view`."""


@dataclass(frozen=True)
class QualityThresholds:
    """When a foot stands, a body pair collides and a limit counts as broken."""

    ground_contact_height_m: float = 0.02
    """A foot is in stance (and its skating counts) while its lowest mesh point is below this height."""
    self_collision_depth_m: float = 0.005
    """A frame self-collides when a configured body pair penetrates deeper than this."""
    joint_limit_tolerance_rad: float = 1e-6
    """Slack beyond the model's joint range before a frame counts as a violation."""
    velocity_limit_tolerance: float = 1e-6
    """Relative slack on each joint's velocity limit."""
    diverged_reference_quantile: float = 0.25
    """The take's typical keypoint error is this quantile of its frames' errors: a low one, which a
    failure through most of the take does not raise (a leg folded onto its alias from the middle of
    H1-2's fast push and fall to its end put the median at 162 mm, where the p25 stayed at 51)."""
    diverged_ratio: float = 3.0
    """A frame has diverged when its keypoint error is this many times the typical error ..."""
    diverged_margin_m: float = 0.15
    """... and at least this much above it (a low typical error alone does not make a frame diverged)."""
    diverged_absolute_m: float = 0.5
    """A frame has also diverged when its keypoint error exceeds this, whatever the typical error:
    a take off its targets in more than three quarters of its frames raises even a low quantile."""
    range_limit_margin_rad: float = 1e-3
    """A joint this close to a bound of its range is held there: the range decided its angle."""


@dataclass(frozen=True)
class FootMeshes:
    """The mesh points of each foot in its body frame; a foot's lowest world point is always one of them."""

    body_names: tuple[str, str]
    """Left and right foot bodies (`RobotConfig.foot_bodies`)."""
    vertices: tuple[np.ndarray, np.ndarray]
    """(V, 3) per foot: convex-hull vertices of the foot body's mesh geoms, in the body frame."""

    @classmethod
    def from_robot(cls, robot: Robot) -> FootMeshes:
        """Every mesh geom of each foot body, visual or collision, whatever its group.

        The G1 collides through four small spheres under the sole; the visual mesh is the foot a viewer
        sees sink into the floor, so that is what penetration is measured on.
        """
        model = robot.model
        per_foot = []
        for body in robot.config.foot_bodies:
            body_id = robot.body_ids[body]
            geoms = [
                g
                for g in range(model.ngeom)
                if model.geom_bodyid[g] == body_id and model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
            ]
            if not geoms:
                raise PipelineError(f"{robot.config.source}: foot body '{body}' has no mesh geom to measure")
            per_foot.append(mesh_hull_in_body(model, tuple(geoms)))
        return cls(body_names=robot.config.foot_bodies, vertices=(per_foot[0], per_foot[1]))

    def lowest_z(self, body_pos_w: np.ndarray, body_quat_w: np.ndarray, body_names: Sequence[str]) -> np.ndarray:
        """(T, 2) lowest world z of each foot's mesh, from body poses (T, B, 3) and (T, B, 4 wxyz)."""
        lowest = np.empty((body_pos_w.shape[0], 2))
        for foot, (body, vertices) in enumerate(zip(self.body_names, self.vertices)):
            if body not in body_names:
                raise PipelineError(f"foot body '{body}' is not among the reference's bodies")
            index = list(body_names).index(body)
            lowest[:, foot] = support_lowest_z(body_pos_w[:, index], body_quat_w[:, index], vertices, 0.0)
        return lowest


def quality_series(
    robot: Robot,
    reference: ReferenceMotion,
    keypoint_targets: np.ndarray | None = None,
    keypoint_bodies: Sequence[str] | None = None,
    human_pelvis: np.ndarray | None = None,
    foot_orientations: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Per-frame rulers on the reference's timeline (for plots and for finding a bad frame).

    `penetration_m`: depth of the deepest point of any collision geom below z = 0, and
    `penetration_body`: the index into `BodyHulls.body_names` of that body (-1: none below).
    `keypoint_error_m`: mean distance of the key bodies to their scaled-human targets.
    `pelvis_height_dev_m`: robot pelvis height minus the scaled human hips height, median offset removed.
    `root_speed_m_s` / `human_root_speed_m_s`: speed of the floating base and of the scaled human hips.
    `planted_foot_turn_deg`: how far the planted feet (`reference.foot_contact`) are turned from their
    target orientations `foot_orientations` (T, 2, 3, 3), the larger of the two; NaN where none is planted.
    """
    if tuple(reference.joint_names) != tuple(robot.config.joint_names):
        raise PipelineError(f"reference joints do not match robot {robot.config.name}'s joint order")
    if reference.n_frames == 0:
        raise PipelineError("reference motion has no frames")
    dt = 1.0 / reference.fps
    hulls = BodyHulls.from_robot(robot)
    penetration, deepest = hulls.deepest_below_floor(reference.body_pos_w, reference.body_quat_w, reference.body_names)
    series = {
        "penetration_m": penetration,
        "penetration_body": deepest,
        "root_speed_m_s": np.linalg.norm(_gradient(reference.root_pos, dt), axis=-1),
    }
    if keypoint_targets is not None:
        series["keypoint_error_m"] = _keypoint_error(reference, keypoint_targets, keypoint_bodies)
    if human_pelvis is not None:
        human_pelvis = np.asarray(human_pelvis, dtype=float)
        if human_pelvis.shape != (reference.n_frames, 3):
            raise PipelineError(f"human_pelvis has shape {human_pelvis.shape}, expected ({reference.n_frames}, 3)")
        root = reference.body_names.index(robot.config.root_body)
        series["pelvis_height_dev_m"] = pelvis_height_deviation(reference.body_pos_w[:, root, 2], human_pelvis[:, 2])
        series["human_root_speed_m_s"] = np.linalg.norm(_gradient(human_pelvis, dt), axis=-1)
    if foot_orientations is not None:
        series["planted_foot_turn_deg"] = _planted_foot_turn(robot, reference, foot_orientations)
    return series


def retarget_quality(
    robot: Robot,
    reference: ReferenceMotion,
    thresholds: QualityThresholds = QualityThresholds(),
    keypoint_targets: np.ndarray | None = None,
    keypoint_bodies: Sequence[str] | None = None,
    frames_per_s: float | None = None,
    human_pelvis: np.ndarray | None = None,
    foot_orientations: np.ndarray | None = None,
) -> dict[str, float | int | str | dict[str, int] | None]:
    """SPEC retargeting metrics of one reference motion, as JSON-ready plain numbers.

    `keypoint_targets` (T, K, 3) are the scaled human positions the bodies `keypoint_bodies` should reach
    and `human_pelvis` (T, 3) the leg-length-scaled human hips; without them the metrics that need them
    are None. `frames_per_s` is the retargeter's throughput, passed through. `skate_stance_mean_mm_s` is
    0.0 when no foot ever comes within the contact height: a clip that never stands cannot skate.
    """
    series = quality_series(robot, reference, keypoint_targets, keypoint_bodies, human_pelvis, foot_orientations)
    return summarize_quality(robot, reference, series, thresholds, frames_per_s)


def summarize_quality(
    robot: Robot,
    reference: ReferenceMotion,
    series: dict[str, np.ndarray],
    thresholds: QualityThresholds = QualityThresholds(),
    frames_per_s: float | None = None,
) -> dict[str, float | int | str | dict[str, int] | None]:
    """`retarget_quality` from per-frame rulers already computed by `quality_series`."""
    dt = 1.0 / reference.fps
    feet, foot_speed = sole_heights_and_speeds(robot, reference)
    feet_penetration = np.maximum(0.0, -feet).max(axis=1)
    stance = feet < thresholds.ground_contact_height_m
    skate = float(foot_speed[stance].mean()) if stance.any() else 0.0
    penetration = series["penetration_m"]
    deepest = int(series["penetration_body"][penetration.argmax()])
    hull_bodies = BodyHulls.from_robot(robot).body_names
    error = series.get("keypoint_error_m")
    pelvis_dev = series.get("pelvis_height_dev_m")
    human_speed = series.get("human_root_speed_m_s")
    foot_turn = series.get("planted_foot_turn_deg")

    return {
        "frames": int(reference.n_frames),
        "fps_frames_per_s": None if frames_per_s is None else _round(frames_per_s),
        "penetration_max_mm": _round(1000.0 * penetration.max()),
        "penetration_p95_mm": _round(1000.0 * np.percentile(penetration, 95.0)),
        "penetration_deepest_body": hull_bodies[deepest] if deepest >= 0 else None,
        "feet_penetration_max_mm": _round(1000.0 * feet_penetration.max()),
        "feet_penetration_p95_mm": _round(1000.0 * np.percentile(feet_penetration, 95.0)),
        "pelvis_height_dev_p95_m": None if pelvis_dev is None else _round(np.percentile(np.abs(pelvis_dev), 95.0)),
        "skate_stance_mean_mm_s": _round(1000.0 * skate),
        "joint_limit_violations": _joint_limit_violations(robot, reference.joint_pos, thresholds),
        **_range_limited(robot, reference.joint_pos, thresholds),
        "velocity_limit_violations": _velocity_limit_violations(robot, reference.joint_pos, dt, thresholds),
        "self_collision_frames": self_collision_frames(robot, reference, thresholds.self_collision_depth_m),
        "jerk_mean": _round(_jerk_mean(reference.joint_pos, dt)),
        "keypoint_error_mean_mm": None if error is None else _round(1000.0 * error.mean()),
        "keypoint_error_p95_mm": None if error is None else _round(1000.0 * np.percentile(error, 95.0)),
        "keypoint_error_max_mm": None if error is None else _round(1000.0 * error.max()),
        "diverged_frames": None if error is None else int(diverged(error, thresholds).sum()),
        "root_speed_p999_m_s": _round(np.percentile(series["root_speed_m_s"], 99.9)),
        "human_root_speed_p999_m_s": None if human_speed is None else _round(np.percentile(human_speed, 99.9)),
        "planted_foot_turn_p95_deg": _planted_turn_p95(foot_turn),
    }


def pelvis_height_deviation(pelvis_z: np.ndarray, human_hips_z: np.ndarray) -> np.ndarray:
    """(T,) the robot pelvis's height over the scaled human hips, its median over the clip removed."""
    difference = pelvis_z - human_hips_z
    return difference - np.median(difference)


def sole_heights_and_speeds(robot: Robot, reference: ReferenceMotion) -> tuple[np.ndarray, np.ndarray]:
    """(T, 2) lowest sole point (m) and horizontal speed (m/s) of the left and right foot: a foot
    skates where it moves while its sole is below `ground_contact_height_m`."""
    soles = FootMeshes.from_robot(robot).lowest_z(reference.body_pos_w, reference.body_quat_w, reference.body_names)
    feet = [reference.body_names.index(body) for body in robot.config.foot_bodies]
    speed = np.linalg.norm(_gradient(reference.body_pos_w[:, feet, :2], 1.0 / reference.fps), axis=-1)
    return soles, speed


def diverged(keypoint_error: np.ndarray, thresholds: QualityThresholds) -> np.ndarray:
    """(T,) bool: frames whose keypoint error is far above the take's typical error (both a ratio
    and a margin), or above the absolute limit."""
    typical = float(np.quantile(keypoint_error, thresholds.diverged_reference_quantile))
    limit = max(thresholds.diverged_ratio * typical, typical + thresholds.diverged_margin_m)
    return (keypoint_error > limit) | (keypoint_error > thresholds.diverged_absolute_m)


def self_collision_frames(robot: Robot, reference: ReferenceMotion, depth_m: float) -> int:
    """Frames where any `collision_pairs` body pair has signed distance below -depth_m (MuJoCo geometry)."""
    return int(colliding_frames(robot, _qpos_trajectory(robot, reference), depth_m).sum())


def colliding_frames(robot: Robot, qpos: np.ndarray, depth_m: float) -> np.ndarray:
    """(T,) bool: some configured body pair is closer than -depth_m (a negative depth asks for clearance)."""
    model = robot.model
    geom_pairs = collision_geom_pairs(robot)
    colliding = np.zeros(len(qpos), dtype=bool)
    if len(geom_pairs) == 0:
        return colliding
    geoms, columns = np.unique(geom_pairs, return_inverse=True)
    columns = columns.reshape(-1, 2)
    data = mujoco.MjData(model)

    # First pass: geom centres only. Two geoms can come this close only where their bounding spheres
    # (grown by the clearance asked for) overlap; on a dance clip few frames need the exact distance.
    centres = np.empty((len(qpos), len(geoms), 3))
    for t in range(len(qpos)):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        centres[t] = data.geom_xpos[geoms]
    # rbound 0 means unbounded (planes, height fields): never prune those.
    radius = np.where(model.geom_rbound[geoms] > 0, model.geom_rbound[geoms], np.inf)
    margin = max(0.0, -depth_m)
    gap = np.linalg.norm(centres[:, columns[:, 0]] - centres[:, columns[:, 1]], axis=-1)
    candidate = gap < radius[columns[:, 0]] + radius[columns[:, 1]] + margin

    for frame in np.flatnonzero(candidate.any(axis=1)):
        data.qpos[:] = qpos[frame]
        mujoco.mj_kinematics(model, data)
        for g1, g2 in geom_pairs[candidate[frame]]:
            # distmax = the clearance asked for: pairs farther apart stop early.
            if mujoco.mj_geomDistance(model, data, int(g1), int(g2), margin, None) < -depth_m:
                colliding[frame] = True
                break
    return colliding


def _qpos_trajectory(robot: Robot, reference: ReferenceMotion) -> np.ndarray:
    """(T, nq): the free joint comes first (checked on load); joints outside the config stay at qpos0."""
    qpos = np.tile(robot.model.qpos0, (reference.n_frames, 1))
    qpos[:, :3] = reference.root_pos
    qpos[:, 3:7] = reference.root_quat / np.linalg.norm(reference.root_quat, axis=1, keepdims=True)
    qpos[:, robot.qpos_indices] = reference.joint_pos
    return qpos


def _joint_limit_violations(robot: Robot, joint_pos: np.ndarray, thresholds: QualityThresholds) -> int:
    model = robot.model
    limited = model.jnt_limited[[model.joint(name).id for name in robot.config.joint_names]].astype(bool)
    low, high = robot.joint_range.T
    tol = thresholds.joint_limit_tolerance_rad
    outside = ((joint_pos < low - tol) | (joint_pos > high + tol)) & limited
    return int(outside.any(axis=1).sum())


def range_limited(robot: Robot, joint_pos: np.ndarray, thresholds: QualityThresholds) -> np.ndarray:
    """(T, J) bool: joint j of frame t is at a bound of the range retargeting keeps it within (the
    margin included), so the range, not the human's pose, decided its angle."""
    low, high = robot.retarget_range.T
    margin = thresholds.range_limit_margin_rad
    return (joint_pos < low + margin) | (joint_pos > high - margin)


def _range_limited(robot: Robot, joint_pos: np.ndarray, thresholds: QualityThresholds) -> dict[str, Any]:
    """`range_limited_frames` (frames where some joint is at a bound) and `range_limited_joints`
    (frames per such joint, most first)."""
    held = range_limited(robot, joint_pos, thresholds)
    per_joint = held.sum(axis=0)
    order = np.argsort(-per_joint, kind="stable")
    names = robot.config.joint_names
    return {
        "range_limited_frames": int(held.any(axis=1).sum()),
        "range_limited_joints": {names[j]: int(per_joint[j]) for j in order if per_joint[j] > 0},
    }


def _velocity_limit_violations(robot: Robot, joint_pos: np.ndarray, dt: float, thresholds: QualityThresholds) -> int:
    limit = robot.config.velocity_limit * (1.0 + thresholds.velocity_limit_tolerance)
    return int((np.abs(_gradient(joint_pos, dt)) > limit).any(axis=1).sum())


def _jerk_mean(joint_pos: np.ndarray, dt: float) -> float:
    """Mean |d3q/dt3| over frames and joints; 0.0 for clips too short to have a third difference."""
    if joint_pos.shape[0] < 4:
        return 0.0
    return float(np.abs(np.diff(joint_pos, n=3, axis=0)).mean() / dt**3)


def _keypoint_error(reference: ReferenceMotion, targets: np.ndarray, bodies: Sequence[str] | None) -> np.ndarray:
    """(T,) mean distance (m) of the key bodies to their targets."""
    if bodies is None:
        raise PipelineError("keypoint_targets given without keypoint_bodies")
    targets = np.asarray(targets, dtype=float)
    if targets.shape != (reference.n_frames, len(bodies), 3):
        raise PipelineError(
            f"keypoint_targets has shape {targets.shape}, expected ({reference.n_frames}, {len(bodies)}, 3)"
        )
    missing = [b for b in bodies if b not in reference.body_names]
    if missing:
        raise PipelineError(f"keypoint body '{missing[0]}' is not among the reference's bodies")
    index = [reference.body_names.index(b) for b in bodies]
    return np.linalg.norm(reference.body_pos_w[:, index] - targets, axis=-1).mean(axis=1)


def _planted_foot_turn(robot: Robot, reference: ReferenceMotion, foot_orientations: np.ndarray) -> np.ndarray:
    """(T,) degrees between each planted foot and its target orientation, the larger foot; NaN if none planted."""
    wanted = np.asarray(foot_orientations, dtype=float)
    if wanted.shape != (reference.n_frames, 2, 3, 3):
        raise PipelineError(f"foot_orientations has shape {wanted.shape}, expected ({reference.n_frames}, 2, 3, 3)")
    turn = np.full((reference.n_frames, 2), np.nan)
    for side, foot in enumerate(robot.config.foot_bodies):
        planted = reference.foot_contact[:, side].astype(bool)
        quat = reference.body_quat_w[planted, reference.body_names.index(foot)]
        offset = Rotation.from_matrix(wanted[planted, side]).inv() * Rotation.from_quat(quat, scalar_first=True)
        turn[planted, side] = np.degrees(offset.magnitude())
    # fmax skips a NaN (an unplanted foot) unless both are.
    return np.fmax(turn[:, 0], turn[:, 1])


def _planted_turn_p95(turn: np.ndarray | None) -> float | None:
    """p95 of the planted-foot turn over the frames that plant a foot; 0.0 for a clip that never does."""
    if turn is None:
        return None
    planted = turn[~np.isnan(turn)]
    return _round(np.percentile(planted, 95.0)) if planted.size else 0.0


def _gradient(values: np.ndarray, dt: float) -> np.ndarray:
    """Central differences along time, one-sided at the ends (as the reference's own velocities)."""
    if values.shape[0] < 2:
        return np.zeros_like(values)
    return np.gradient(values, dt, axis=0)


def _round(value: float) -> float:
    return round(float(value), 3)
