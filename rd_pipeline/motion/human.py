"""Human motion: global joint positions and orientations of a mocap skeleton (the `parse` artifact)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from rd_pipeline.files import open_npz
from rd_pipeline.motion.bvh import BvhClip, forward_kinematics
from rd_pipeline.motion.lafan import LAFAN_CM_TO_M, LAFAN_TO_Z_UP  # noqa: F401 (re-exported)

HUMAN_MOTION_FILE = "human_motion.npz"
"""File name of a human motion inside an artifact."""


@dataclass(frozen=True)
class HumanMotion:
    """A skeleton over time, Z-up, metres."""

    fps: float
    """Frames per second of the source."""
    names: tuple[str, ...]
    """Joint names (End Sites as `<parent>_end`)."""
    parents: np.ndarray
    """(J,) parent index, -1 for the root."""
    offsets: np.ndarray
    """(J, 3) rest offsets from the parent, metres, in the parent's frame."""
    pos_w: np.ndarray
    """(T, J, 3) global joint positions."""
    quat_w: np.ndarray
    """(T, J, 4) global joint orientations, wxyz."""

    @property
    def n_frames(self) -> int:
        return self.pos_w.shape[0]

    @property
    def duration_s(self) -> float:
        return self.n_frames / self.fps

    def save(self, path: Path) -> None:
        np.savez(
            path,
            fps=self.fps,
            names=np.array(self.names),
            parents=self.parents,
            offsets=self.offsets,
            pos_w=self.pos_w,
            quat_w=self.quat_w,
        )

    @classmethod
    def load(cls, path: Path) -> HumanMotion:
        with open_npz(path) as data:
            return cls(
                fps=float(data["fps"]),
                names=tuple(str(n) for n in data["names"]),
                parents=data["parents"],
                offsets=data["offsets"],
                pos_w=data["pos_w"],
                quat_w=data["quat_w"],
            )


def human_motion_from_bvh(clip: BvhClip, length_unit_m: float, up_axis_change: np.ndarray) -> HumanMotion:
    """Forward kinematics of a BVH clip, converted to metres and a Z-up world."""
    pos, rot = forward_kinematics(clip)
    pos_w = np.einsum("ab,tjb->tja", up_axis_change, pos) * length_unit_m
    rot_w = np.einsum("ab,tjbc->tjac", up_axis_change, rot)
    quat_xyzw = Rotation.from_matrix(rot_w.reshape(-1, 3, 3)).as_quat()
    quat_w = quat_xyzw[:, [3, 0, 1, 2]].reshape(*rot_w.shape[:2], 4)
    offsets = np.array([j.offset for j in clip.joints]) * length_unit_m
    return HumanMotion(
        fps=1.0 / clip.frame_time,
        names=tuple(clip.names),
        parents=clip.parents,
        offsets=offsets,
        pos_w=pos_w,
        quat_w=quat_w,
    )
