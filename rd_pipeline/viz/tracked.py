"""`tracked.npz`: the policy's start-zero sim2sim rollout as `validate` keeps it for recordings."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rd_pipeline.files import open_npz

TRACKED_FILE = "tracked.npz"


@dataclass(frozen=True)
class TrackedRollout:
    """Body poses and per-step errors of one rollout, and what ended it.

    Pose k is at reference frame `first_frame + k`; error k is measured after control step k,
    so it belongs to pose k + 1 (one control step per reference frame).
    """

    body_pos: np.ndarray
    """(steps + 1, nbody, 3) world positions of every model body."""
    body_quat: np.ndarray
    """(steps + 1, nbody, 4) wxyz."""
    first_frame: int
    """Reference frame the rollout started on."""
    fps: float
    """Reference frames (and control steps) per second."""
    body_error_m: np.ndarray
    """(steps,) mean pelvis-relative body position error, the one the report's tracked % uses."""
    joint_error_rad: np.ndarray
    """(steps,) mean joint position error."""
    ended_by: str
    """The failure that ended it (`tilted`, `far <body>`, `floor <body>`, joined by ` + `);
    empty when it reached the end of the reference."""

    @property
    def steps(self) -> int:
        return len(self.body_error_m)

    def save(self, path: Path) -> None:
        np.savez(
            path,
            body_pos=self.body_pos,
            body_quat=self.body_quat,
            first_frame=self.first_frame,
            fps=self.fps,
            body_error_m=self.body_error_m,
            joint_error_rad=self.joint_error_rad,
            ended_by=self.ended_by,
        )

    @classmethod
    def load(cls, path: Path) -> TrackedRollout:
        with open_npz(path) as data:
            return cls(
                body_pos=data["body_pos"],
                body_quat=data["body_quat"],
                first_frame=int(data["first_frame"]),
                fps=float(data["fps"]),
                body_error_m=data["body_error_m"],
                joint_error_rad=data["joint_error_rad"],
                ended_by=str(data["ended_by"]),
            )
