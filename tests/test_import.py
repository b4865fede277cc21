"""Importing LAFAN1_Retargeting_Dataset CSVs into 50 Hz reference motions."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from conftest import RETARGETED_DIR, cli
from scipy.spatial.transform import Rotation

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.contact import ContactThresholds
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.motion.retargeted_csv import import_retargeted_csv
from rd_pipeline.robots import load_robot


def _import(robot: str, motion: str, interpolation: str = "cubic"):
    return import_retargeted_csv(
        RETARGETED_DIR / robot / f"{motion}.csv", load_robot(robot), 30.0, 50.0, interpolation, ContactThresholds()
    )


@pytest.fixture(scope="module")
def h1_2_dance2() -> tuple[ReferenceMotion, np.ndarray]:
    table = np.loadtxt(RETARGETED_DIR / "h1_2" / "dance2_subject4.csv", delimiter=",")
    return _import("h1_2", "dance2_subject4").reference, table


def test_duration_and_shapes(h1_2_dance2) -> None:
    reference, table = h1_2_dance2
    assert table.shape == (6771, 34)
    assert reference.fps == 50.0
    assert reference.n_frames == 11285
    assert reference.duration_s == pytest.approx(225.7)
    assert reference.joint_pos.shape == (11285, 27)
    assert reference.body_pos_w.shape == (11285, 28, 3)  # every body but the world
    assert reference.foot_contact.shape == (11285, 2) and reference.foot_contact.dtype == bool


def test_samples_on_the_common_grid_equal_the_csv(h1_2_dance2) -> None:
    reference, table = h1_2_dance2
    # Every 0.1 s both grids meet: CSV frame 3k is reference frame 5k.
    src, dst = np.arange(0, 6771, 3), np.arange(0, 11285, 5)
    assert np.abs(reference.joint_pos[dst] - table[src, 7:]).max() < 1e-9
    assert np.abs(reference.root_pos[dst] - table[src, :3]).max() < 1e-9
    csv_rot = Rotation.from_quat(table[src, 3:7])
    ref_rot = Rotation.from_quat(reference.root_quat[dst][:, [1, 2, 3, 0]])
    assert np.abs((csv_rot.inv() * ref_rot).magnitude()).max() < 1e-9


def test_body_poses_are_mujoco_fk(h1_2_dance2) -> None:
    reference, _ = h1_2_dance2
    robot = load_robot("h1_2")
    data = mujoco.MjData(robot.model)
    for t in (0, 777, 11284):
        data.qpos[:3], data.qpos[3:7] = reference.root_pos[t], reference.root_quat[t]
        data.qpos[robot.qpos_indices] = reference.joint_pos[t]
        mujoco.mj_kinematics(robot.model, data)
        assert np.abs(reference.body_pos_w[t] - data.xpos[1:]).max() < 1e-12
    pelvis = reference.body_names.index("pelvis")
    assert np.abs(reference.body_pos_w[:, pelvis] - reference.root_pos).max() < 1e-12


def test_velocities_are_consistent_with_positions(h1_2_dance2) -> None:
    reference, _ = h1_2_dance2
    dt = 1.0 / reference.fps
    # Central differences: the mean velocity over two steps equals the displacement over them.
    midpoint = (reference.joint_pos[2:] - reference.joint_pos[:-2]) / (2 * dt)
    assert np.abs(reference.joint_vel[1:-1] - midpoint).max() < 1e-9
    torso = reference.body_names.index("torso_link")
    rot = Rotation.from_quat(reference.body_quat_w[:, torso][:, [1, 2, 3, 0]])
    t = 4000
    step = rot[t + 1] * rot[t - 1].inv()
    assert np.allclose(reference.body_ang_vel_w[t, torso], step.as_rotvec() / (2 * dt), atol=1e-9)
    # Plausible magnitudes for a dance: joint speed rarely beyond 15 rad/s.
    assert np.percentile(np.abs(reference.joint_vel), 99.9) < 15.0


def test_contacts_alternate_between_feet(h1_2_dance2) -> None:
    reference, _ = h1_2_dance2
    either = reference.foot_contact.any(axis=1).mean()
    both = reference.foot_contact.all(axis=1).mean()
    assert 0.3 < either <= 1.0 and both < either
    # Each foot carries the dancer alone for a real share of the frames.
    left_only = (reference.foot_contact[:, 0] & ~reference.foot_contact[:, 1]).mean()
    right_only = (reference.foot_contact[:, 1] & ~reference.foot_contact[:, 0]).mean()
    assert left_only > 0.05 and right_only > 0.05


def test_ground_percentile_sets_the_ground_the_feet_stand_on(h1_2_dance2) -> None:
    reference, _ = h1_2_dance2
    csv = RETARGETED_DIR / "h1_2" / "dance2_subject4.csv"
    lowest = ContactThresholds(ground_percentile=0.0)
    on_lowest = import_retargeted_csv(csv, load_robot("h1_2"), 30.0, 50.0, "cubic", lowest).reference
    # The single lowest foot frame lies below the floor the dancer stands on: measured from it, a
    # planted foot hovers above the enter height in half of the frames the default calls planted.
    assert reference.foot_contact.mean() == pytest.approx(0.381, abs=0.005)
    assert on_lowest.foot_contact.mean() == pytest.approx(0.208, abs=0.005)


def test_g1_maps_29_dof_dataset_by_name() -> None:
    result = _import("g1", "dance1_subject2")
    assert result.dropped_joints == (
        "waist_roll_joint",
        "waist_pitch_joint",
        "left_wrist_pitch_joint",
        "left_wrist_yaw_joint",
        "right_wrist_pitch_joint",
        "right_wrist_yaw_joint",
    )
    table = np.loadtxt(RETARGETED_DIR / "g1" / "dance1_subject2.csv", delimiter=",")
    robot = load_robot("g1")
    knee = robot.config.joint_names.index("right_knee_joint")
    shoulder = robot.config.joint_names.index("right_shoulder_pitch_joint")
    assert np.allclose(result.reference.joint_pos[::5, knee], table[::3, 7 + 9])
    assert np.allclose(result.reference.joint_pos[::5, shoulder], table[::3, 7 + 22])
    assert result.reference.n_frames == round(3945 * 50 / 30)


def test_bad_csv_lines_are_named(tmp_path: Path) -> None:
    source = (RETARGETED_DIR / "h1" / "dance1_subject1.csv").read_text().splitlines()
    source[41] = source[41].rsplit(",", 1)[0]
    path = tmp_path / "h1" / "dance1_subject1.csv"
    path.parent.mkdir()
    path.write_text("\n".join(source) + "\n")
    with pytest.raises(PipelineError, match=rf"^{path}:42: expected 26 values, got 25$"):
        import_retargeted_csv(path, load_robot("h1"), 30.0, 50.0, "cubic", ContactThresholds())
    result = cli(
        "stage",
        "import",
        "--robot",
        "h1",
        "--motion",
        "dance1_subject1",
        env={"RD_RETARGETED_DIR": str(tmp_path), "RD_ARTIFACTS": str(tmp_path / "store")},
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert f"error: {path}:42: expected 26 values, got 25" in result.stderr
    assert not list((tmp_path / "store" / "import" / "h1" / "dance1_subject1").glob("[!.]*"))


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        ("inf", "{path}:7: non-finite value 'inf'"),
        ("quaternion", "{path}:7: root quaternion has norm 0.000"),
        ("latin-1", "{path}: not a text CSV (invalid continuation byte at byte 0)"),
    ],
)
def test_a_damaged_csv_is_named_at_its_file_line(damage: str, message: str, tmp_path: Path) -> None:
    """Blank lines count: line numbers are the file's, not the rows'."""
    rows = (RETARGETED_DIR / "h1" / "dance1_subject1.csv").read_text().splitlines()[:20]
    fields = rows[4].split(",")
    if damage == "inf":
        fields[8] = "inf"
    elif damage == "quaternion":
        fields[3:7] = ["0", "0", "0", "0"]
    text = "\n".join(["", "", *rows[:4], ",".join(fields), "", *rows[5:]]) + "\n"
    path = tmp_path / "dance1_subject1.csv"
    path.write_bytes(b"\xe9" + text.encode() if damage == "latin-1" else text.encode())
    with pytest.raises(PipelineError) as error:
        import_retargeted_csv(path, load_robot("h1"), 30.0, 50.0, "cubic", ContactThresholds())
    assert str(error.value) == message.format(path=path)


@pytest.mark.slow
def test_cli_import_writes_the_reference_artifact(artifacts: Path) -> None:
    result = cli("stage", "import", "--robot", "h1_2", "--motion", "dance2_subject4")
    assert result.returncode == 0, result.stderr
    (folder,) = (artifacts / "import" / "h1_2" / "dance2_subject4").iterdir()
    reference = ReferenceMotion.load(folder / "reference.npz")
    assert reference.fps == 50.0 and reference.duration_s == pytest.approx(225.7)
    manifest = (folder / "manifest.json").read_text()
    assert '"fps": 50.0' in manifest and '"frames": 11285' in manifest


@pytest.mark.slow
def test_renormalised_quaternions_are_counted_in_a_warning(tmp_path: Path) -> None:
    rows = (RETARGETED_DIR / "h1" / "dance1_subject1.csv").read_text().splitlines()
    for line in (10, 11, 500):  # three rows with their quaternion scaled by 1.5
        fields = rows[line - 1].split(",")
        fields[3:7] = [repr(1.5 * float(v)) for v in fields[3:7]]
        rows[line - 1] = ",".join(fields)
    path = tmp_path / "h1" / "dance1_subject1.csv"
    path.parent.mkdir()
    path.write_text("\n".join(rows) + "\n")
    result = import_retargeted_csv(path, load_robot("h1"), 30.0, 50.0, "cubic", ContactThresholds())
    (warning,) = result.warnings
    assert warning == (
        f"{path}: 3 of {len(rows)} root quaternions are not of unit norm and were renormalised "
        "(first at line 10, norm 1.500)"
    )
    clean = import_retargeted_csv(
        RETARGETED_DIR / "h1" / "dance1_subject1.csv", load_robot("h1"), 30.0, 50.0, "cubic", ContactThresholds()
    )
    assert clean.warnings == ()
    assert np.allclose(result.reference.root_quat, clean.reference.root_quat, atol=1e-9)  # same motion
    said = cli(
        "run",
        "--robot",
        "h1",
        "--motion",
        "dance1_subject1",
        "--source",
        "csv",
        "--until",
        "import",
        env={"RD_RETARGETED_DIR": str(tmp_path), "RD_ARTIFACTS": str(tmp_path / "store")},
    )
    assert said.returncode == 0, said.stderr
    assert f"warning: {warning}" in " ".join(said.stderr.split())
