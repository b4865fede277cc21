"""Leg targets a robot can reach: its own stance width, crossed legs opened, the body lowered where a
leg is too short for its foot."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from rd_pipeline.retarget.lafan_joints import FEET, HIPS_LR, KNEES, PELVIS
from rd_pipeline.retarget.smoothing import smooth_cover


def match_stance_width(targets: dict[str, np.ndarray], rest: dict[str, np.ndarray], pelvis: np.ndarray) -> None:
    """Move each leg sideways (in the pelvis frame) so the typical stance width is the robot's own.

    A narrow human stance scaled onto a robot with wide hips and little hip roll (H1: +-0.43 rad)
    asks for feet the robot cannot bring together; the offset is the robot's rest foot width minus
    the clip's median, a constant per leg.
    """
    for knee, foot in zip(KNEES, FEET):
        lateral = np.einsum("ti,ti->t", pelvis[:, :, 1], targets[foot] - targets[PELVIS])
        robot_lateral = float((rest[foot] - rest[PELVIS])[1])  # rest frames are world-aligned
        shift = (robot_lateral - float(np.median(lateral))) * pelvis[:, :, 1]
        targets[knee] = targets[knee] + shift
        targets[foot] = targets[foot] + shift


def keep_feet_apart(
    targets: dict[str, np.ndarray],
    rest: dict[str, np.ndarray],
    pelvis: np.ndarray,
    fps: float,
    fraction: float,
    smoothing_s: float,
    line_smoothing_s: float,
) -> None:
    """Push the legs apart where the feet come horizontally closer than `fraction` of the robot's rest
    stance: a human crosses and passes legs closer than a robot's thick knees and feet can.

    The push is along the line between the feet (sideways when they pass each other, whatever the
    pelvis does in a turn), a smooth cover of the per-frame deficit shared by both legs; planting
    picks it up.
    """
    between = (targets[FEET[0]] - targets[FEET[1]])[:, :2]
    distance = np.linalg.norm(between, axis=1)
    # Feet exactly on top of each other have no line between them: use the pelvis' left.
    direction = np.where(distance[:, None] > 1e-6, between / np.maximum(distance, 1e-6)[:, None], pelvis[:, :2, 1])
    direction = gaussian_filter1d(direction, line_smoothing_s * fps, axis=0, mode="nearest")
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    rest_distance = float(np.linalg.norm((rest[FEET[0]] - rest[FEET[1]])[:2]))
    push = smooth_cover(np.maximum(fraction * rest_distance - distance, 0.0), fps, smoothing_s)
    for knee, foot, sign in zip(KNEES, FEET, (0.5, -0.5)):
        shift = np.zeros_like(targets[foot])
        shift[:, :2] = sign * push[:, None] * direction
        targets[knee] = targets[knee] + shift
        targets[foot] = targets[foot] + shift


def keep_legs_reachable(
    targets: dict[str, np.ndarray],
    rest: dict[str, np.ndarray],
    fps: float,
    fraction: float,
    smoothing_s: float,
) -> None:
    """Lower the body (not the feet) where a foot would need a leg longer than the robot's.

    The hip is brought along the leg towards the foot until the leg fits, and the body drops by
    the vertical part of that move: by the whole excess under a vertical leg, by little under a leg
    stretched out along the floor (a lunge, sitting, lying), continuously in between. Dropping
    straight down until the leg fits would instead ask a nearly horizontal leg for the body's whole
    height, pushing the hands and trunk of a lying or lunging body through the floor. The drop is a
    smooth cover of the per-frame requirement, so it adds no jerk.
    """
    need = np.zeros(targets[PELVIS].shape[0])
    for hip, foot in zip(HIPS_LR, FEET):
        reach = fraction * np.linalg.norm(rest[hip] - rest[foot])  # legs are straight in the rest pose
        delta = targets[hip] - targets[foot]
        length = np.maximum(np.linalg.norm(delta, axis=1), reach)
        need = np.maximum(need, delta[:, 2] * (1.0 - reach / length))
    drop = smooth_cover(np.maximum(need, 0.0), fps, smoothing_s)
    for joint in targets:
        # A knee sits between a lowered hip and a foot that stays: it comes down about half as far.
        share = 0.0 if joint in FEET else 0.5 if joint in KNEES else 1.0
        targets[joint] = targets[joint] - share * drop[:, None] * np.array([0.0, 0.0, 1.0])
