"""`rd-pipeline export-motion`: the reference as a dataset CSV that imports back to the same motion."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import RETARGETED_DIR, cli
from scipy.spatial.transform import Rotation

from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.robots import load_robot


def _exported(artifacts: Path, tmp_path: Path, robot: str, motion: str) -> tuple[Path, ReferenceMotion]:
    out = tmp_path / f"{robot}.csv"
    result = cli("export-motion", "--robot", robot, "--motion", motion, "--source", "csv", "--out", str(out))
    assert result.returncode == 0, result.stderr
    (folder,) = list((artifacts / "import" / robot / motion).iterdir())
    return out, ReferenceMotion.load(folder / "reference.npz")


def test_csv_round_trip_is_the_same_motion_within_interpolation_error(artifacts: Path, tmp_path: Path) -> None:
    out, reference = _exported(artifacts, tmp_path, "h1_2", "dance2_subject4")
    robot = load_robot("h1_2")
    back = import_retargeted_csv(out, robot, 30.0, 50.0, "cubic", ContactThresholds()).reference
    assert back.n_frames == reference.n_frames == 11285
    joint_error = np.abs(back.joint_pos - reference.joint_pos)
    assert np.median(joint_error) < 1e-4 and np.percentile(joint_error, 99) < 3e-3
    assert np.abs(back.root_pos - reference.root_pos).max() < 2e-3
    turned = Rotation.from_quat(back.root_quat, scalar_first=True).inv() * Rotation.from_quat(
        reference.root_quat, scalar_first=True
    )
    assert np.percentile(turned.magnitude(), 99) < 0.01


def test_csv_has_the_dataset_layout(artifacts: Path, tmp_path: Path) -> None:
    """The imported G1 motion written back equals the 29-joint dataset file it came from, except the
    six joints the 23-DoF model lacks (waist roll and pitch, wrist pitch and yaw: written as 0) and
    where 30 -> 50 -> 30 Hz smooths."""
    out, _ = _exported(artifacts, tmp_path, "g1", "dance1_subject2")
    written = np.loadtxt(out, delimiter=",")
    source = np.loadtxt(RETARGETED_DIR / "g1" / "dance1_subject2.csv", delimiter=",")
    assert written.shape == source.shape == (3945, 36)
    np.testing.assert_allclose(written[0, :3], source[0, :3], atol=1e-9)
    kept = [c for c in range(7, 36) if written[:, c].any()]
    assert len(kept) == 23
    assert np.median(np.abs(written[:, kept] - source[:, kept])) < 1e-4
    assert np.linalg.norm(written[:, 3:7], axis=1) == pytest.approx(1.0)


def test_a_bad_rate_is_one_line(artifacts: Path, tmp_path: Path) -> None:
    result = cli("export-motion", "--robot", "h1", "--motion", "dance2_subject3", "--fps", "0", "--out", "x.csv")
    assert result.returncode == 2 and result.stderr.strip().endswith("error: --fps must be positive, got 0")
