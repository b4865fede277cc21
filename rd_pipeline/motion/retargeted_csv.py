"""LAFAN1_Retargeting_Dataset CSVs: root xyz, root quaternion xyzw, joint angles; 30 fps; no header."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import interp1d
from scipy.spatial.transform import Rotation, Slerp

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion import QUATERNION_NORM_TOLERANCE, Interpolation, too_short
from rd_pipeline.motion.bvh import is_float
from rd_pipeline.motion.contact import ContactThresholds, label_contacts
from rd_pipeline.motion.reference import ReferenceMotion, reference_from_joint_trajectory
from rd_pipeline.robots import Robot


@dataclass(frozen=True)
class CsvImportResult:
    """An imported reference motion and what the mapping onto the configured model left out."""

    reference: ReferenceMotion
    """The motion on the configured robot, resampled."""
    dropped_joints: tuple[str, ...]
    """Dataset joints the configured model does not have (e.g. the 29-DoF G1's waist roll/pitch)."""
    source_frames: int
    """Rows in the CSV."""
    warnings: tuple[str, ...] = ()
    """What was read but repaired (renormalised quaternions), one line each."""


@dataclass(frozen=True)
class CsvTable:
    """The numbers of a dataset CSV and where each row stands in the file."""

    rows: np.ndarray
    """(T, 7 + joints) root position, root quaternion (xyzw), joint positions."""
    line_numbers: np.ndarray
    """(T,) the file line of each row (blank lines are skipped)."""


def read_retargeted_csv(path: Path, n_joints: int) -> CsvTable:
    """The rows of a dataset CSV; a malformed row is reported with its line number."""
    rows = []
    line_numbers = []
    try:
        with path.open() as handle:
            for line_no, line in enumerate(handle, start=1):
                if not line.strip():
                    continue
                rows.append(_parse_row(path, line_no, line, n_joints))
                line_numbers.append(line_no)
    except UnicodeDecodeError as exc:
        raise PipelineError(f"{path}: not a text CSV ({exc.reason} at byte {exc.start})") from None
    if len(rows) < 2:
        raise PipelineError(f"{path}: needs at least 2 frames, got {len(rows)}")
    return CsvTable(np.array(rows), np.array(line_numbers))


def _parse_row(path: Path, line_no: int, line: str, n_joints: int) -> list[float]:
    parts = line.strip().split(",")
    if len(parts) != 7 + n_joints:
        raise PipelineError(f"{path}:{line_no}: expected {7 + n_joints} values, got {len(parts)}")
    try:
        row = [float(p) for p in parts]
    except ValueError:
        bad = next(p for p in parts if not is_float(p))
        raise PipelineError(f"{path}:{line_no}: non-numeric value '{bad}'") from None
    unusable = [p for p, value in zip(parts, row) if not np.isfinite(value)]
    if unusable:
        raise PipelineError(f"{path}:{line_no}: non-finite value '{unusable[0]}'")
    return row


def import_retargeted_csv(
    path: Path,
    robot: Robot,
    source_fps: float,
    target_fps: float,
    interpolation: Interpolation,
    contact: ContactThresholds,
) -> CsvImportResult:
    """Map dataset columns onto the robot by joint name, resample to `target_fps`, complete by FK."""
    config = robot.config
    csv = read_retargeted_csv(path, len(config.csv_joints))
    table = csv.rows
    quat_norm = np.linalg.norm(table[:, 3:7], axis=1)
    if np.any(quat_norm < 0.5):
        row = int(np.argmax(quat_norm < 0.5))
        raise PipelineError(f"{path}:{csv.line_numbers[row]}: root quaternion has norm {quat_norm[row]:.3f}")
    warnings = _renormalised(path, quat_norm, csv.line_numbers)
    columns = {name: 7 + i for i, name in enumerate(config.csv_joints)}
    missing = [j for j in config.joint_names if j not in columns]
    if missing:
        raise PipelineError(f"{path}: dataset has no column for joint '{missing[0]}' of robot {config.name}")
    dropped = tuple(j for j in config.csv_joints if j not in config.joint_names)

    n_source = table.shape[0]
    short = too_short(str(path), n_source, source_fps)
    if short:
        raise PipelineError(short)
    source_t = np.arange(n_source) / source_fps
    # Same duration as the source (frames / fps); the last target sample holds the last source frame.
    n_target = int(round(n_source * target_fps / source_fps))
    target_t = np.minimum(np.arange(n_target) / target_fps, source_t[-1])

    joint_cols = [columns[j] for j in config.joint_names]
    joint_pos = interp1d(source_t, table[:, joint_cols], kind=interpolation, axis=0)(target_t)
    root_pos = interp1d(source_t, table[:, :3], kind=interpolation, axis=0)(target_t)
    root_rot = Slerp(source_t, Rotation.from_quat(table[:, 3:7]))(target_t)  # CSV quaternions are xyzw
    root_quat = root_rot.as_quat()[:, [3, 0, 1, 2]]

    reference = reference_from_joint_trajectory(
        robot, target_fps, root_pos, root_quat, joint_pos, np.zeros((n_target, 2), dtype=bool)
    )
    foot_idx = [reference.body_names.index(b) for b in config.foot_bodies]
    foot_pos = reference.body_pos_w[:, foot_idx]
    # The dataset's feet are not at z = 0; take its own lowest foot height as the ground.
    ground_z = float(np.percentile(foot_pos[..., 2].min(axis=1), contact.ground_percentile))
    labels = label_contacts(foot_pos, target_fps, ground_z, contact)
    reference = dataclasses.replace(reference, foot_contact=labels)
    return CsvImportResult(reference=reference, dropped_joints=dropped, source_frames=n_source, warnings=warnings)


def _renormalised(path: Path, quat_norm: np.ndarray, line_numbers: np.ndarray) -> tuple[str, ...]:
    """A warning counting the root quaternions that are not of unit norm (Slerp normalises them)."""
    off = np.abs(quat_norm - 1.0) > QUATERNION_NORM_TOLERANCE
    if not off.any():
        return ()
    row = int(np.argmax(off))
    return (
        f"{path}: {int(off.sum())} of {len(quat_norm)} root quaternions are not of unit norm and were "
        f"renormalised (first at line {line_numbers[row]}, norm {quat_norm[row]:.3f})",
    )
