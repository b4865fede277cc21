"""Orientation frames built from keypoint positions, so human and robot frames are built the same way.

A frame is x forward, y left, z up, from an "up" direction and a "left" direction. Building the
robot's frame from its own keypoints in its default pose gives the constant offset between that
geometric frame and the robot's body frame: the rest-pose rotation offset, from the model alone.
"""

from __future__ import annotations

import numpy as np


def frame_from_axes(up: np.ndarray, left: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation with columns forward, left, up; `left` is made orthogonal to `up`."""
    z = up / np.linalg.norm(up, axis=-1, keepdims=True)
    y = left - np.sum(left * z, axis=-1, keepdims=True) * z
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=-1)


def yaw_pitch_frame(yaw: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """(..., 3, 3) frame heading `yaw` with its x axis raised by `pitch` (rad), no roll."""
    yaw, pitch = np.broadcast_arrays(np.asarray(yaw, dtype=float), np.asarray(pitch, dtype=float))
    x = np.stack([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)], axis=-1)
    y = np.stack([-np.sin(yaw), np.cos(yaw), np.zeros_like(yaw)], axis=-1)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def yaw_and_pitch(forward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Heading and elevation (rad) of direction vectors (..., 3)."""
    return np.arctan2(forward[..., 1], forward[..., 0]), np.arctan2(
        forward[..., 2], np.linalg.norm(forward[..., :2], axis=-1)
    )
