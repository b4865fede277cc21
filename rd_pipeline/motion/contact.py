"""Foot contact labels from foot height and horizontal speed, with hysteresis."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rd_pipeline.params import require_at_most


@dataclass(frozen=True)
class ContactThresholds:
    """When a foot (or another body part) counts as planted. Heights are above the clip's ground level."""

    enter_height_m: float = 0.03
    """A free foot lands when it is below this height ..."""
    enter_speed_m_s: float = 0.25
    """... and moves horizontally slower than this."""
    exit_height_m: float = 0.06
    """A planted foot lifts off above this height ..."""
    exit_speed_m_s: float = 0.5
    """... or when it moves horizontally faster than this."""
    ground_percentile: float = 1.0
    """Percentile of the clip's own foot heights taken as its ground, so that a few frames of foot
    noise below the floor do not raise every height; bodies measured against LAFAN1's floor (z = 0)
    do not use it."""

    def __post_init__(self) -> None:
        require_at_most(self, 100.0, "ground_percentile")


def label_contacts(foot_pos: np.ndarray, fps: float, ground_z: float, thresholds: ContactThresholds) -> np.ndarray:
    """(T, F) bool contact labels for foot positions (T, F, 3)."""
    height = foot_pos[..., 2] - ground_z
    if foot_pos.shape[0] > 1:
        speed = np.linalg.norm(np.gradient(foot_pos[..., :2], 1.0 / fps, axis=0), axis=-1)
    else:
        speed = np.zeros(height.shape)
    may_enter = (height < thresholds.enter_height_m) & (speed < thresholds.enter_speed_m_s)
    must_exit = (height > thresholds.exit_height_m) | (speed > thresholds.exit_speed_m_s)
    contact = np.zeros(height.shape, dtype=bool)
    state = may_enter[0].copy()
    for t in range(height.shape[0]):
        state = np.where(state, ~must_exit[t], may_enter[t])
        contact[t] = state
    return contact


def contact_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) of each run of True in a (T,) mask."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))
