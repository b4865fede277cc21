"""How a reference stands: per second, how often a foot is planted and how flat the lowest foot is.

Joint speed tells dance from standing; it does not tell a flat-footed step from one on the balls
of the feet. A reference whose lowest foot is tilted and whose contact labels see no planted foot
asks a flat-soled robot to balance on a sole's edge, which zero action and a policy alike may
not survive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from rd_pipeline.motion.reference import ReferenceMotion


@dataclass(frozen=True)
class Footing:
    """One second of a reference: its support and the tilt of its lowest foot."""

    start_s: int
    """First second of the stretch (from the reference's start)."""
    planted_share: float
    """Share of its frames with at least one foot labelled planted."""
    lowest_foot_tilt_deg: float
    """Median angle between the lowest foot's up axis and the vertical, degrees."""


def footing_per_second(reference: ReferenceMotion, feet: tuple[str, ...]) -> list[Footing]:
    """One `Footing` per second of `reference` (the last, partial one included); `feet` names the
    foot bodies, whose up axis is vertical when the sole is flat."""
    missing = [foot for foot in feet if foot not in reference.body_names]
    if missing:
        raise ValueError(f"reference has no foot body '{missing[0]}'")
    tilt = _lowest_foot_tilt_deg(reference, [reference.body_names.index(foot) for foot in feet])
    planted = np.asarray(reference.foot_contact.any(axis=1))
    return [
        Footing(
            start_s=index,
            planted_share=round(float(planted[second].mean()), 3),
            lowest_foot_tilt_deg=round(float(np.median(tilt[second])), 1),
        )
        for index, second in enumerate(reference.seconds())
    ]


def _lowest_foot_tilt_deg(reference: ReferenceMotion, feet: list[int]) -> np.ndarray:
    """(T,) tilt of the lower foot in each frame, degrees."""
    frames = np.arange(reference.n_frames)
    lowest = np.asarray(feet)[reference.body_pos_w[:, feet, 2].argmin(axis=1)]
    quat_wxyz = reference.body_quat_w[frames, lowest]
    up_z = Rotation.from_quat(quat_wxyz[:, [1, 2, 3, 0]]).as_matrix()[:, 2, 2]
    return np.degrees(np.arccos(np.clip(up_z, -1.0, 1.0)))
