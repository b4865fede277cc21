"""`rd-pipeline export-motion`: the reference as a dataset CSV that imports back to the same motion."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from conftest import RETARGETED_DIR, ReferenceSeeds, cli
from scipy.spatial.transform import Rotation

from rd_pipeline.export.motion_mjlab import hinge_names, task_model
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


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.parametrize("fps", ["0", "0.001", "1e9", "inf", "nan"])
def test_a_bad_rate_is_one_line(artifacts: Path, tmp_path: Path, fps: str) -> None:
    """0.001 fps wrote an empty file; 1e9 asked numpy for 1.64 TiB; inf overflowed."""
    out = tmp_path / "x.csv"
    result = cli("export-motion", "--robot", "h1", "--motion", "dance2_subject3", "--fps", fps, "--out", str(out))
    shown = f"{float(fps):g}"
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [f"error: --fps must be from 1 to 1000 frames per second, got {shown}"]
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.parametrize("format", ["csv", "mjlab"])
def test_an_unwritable_out_is_one_line_and_leaves_no_partial_file(format: str, artifacts: Path, tmp_path: Path) -> None:
    taken = tmp_path / "out" / "taken"
    taken.mkdir(parents=True)  # a folder where the file should go
    args = ["export-motion", "--robot", "h1_2", "--motion", "dance2_subject4", "--format", format]
    result = cli(*args, "--out", str(taken))
    assert result.returncode == 2
    assert result.stderr.strip().splitlines()[-1] == f"error: cannot write {taken} (Is a directory)"
    assert [path.name for path in taken.parent.iterdir()] == ["taken"]


@pytest.mark.slow
@pytest.mark.parametrize(("robot_name", "fps"), [("g1", None), ("h1_2", 30.0)])
def test_mjlab_npz_follows_the_task_model_order_and_its_kinematics(
    robot_name: str, fps: float | None, artifacts: Path, tmp_path: Path
) -> None:
    """The contract of mjlab's `MotionLoader`: joints in the task model's hinge order, every body but
    the world in its order, wxyz quaternions; checked by forward kinematics on that model. For G1 the
    task model is the 29-DoF G1 with mjlab's torso frame (bench/mjlab_interop.py checks it against
    mjlab itself); H1-2 has no mjlab task and keeps its own model."""
    motion = {"g1": "dance1_subject2", "h1_2": "dance2_subject4"}[robot_name]
    out = tmp_path / f"{robot_name}.npz"
    args = ["export-motion", "--robot", robot_name, "--motion", motion, "--source", "csv", "--format", "mjlab"]
    result = cli(*args, "--out", str(out), *(["--fps", str(fps)] if fps else []))
    assert result.returncode == 0, result.stderr
    robot = load_robot(robot_name)
    model, offsets = task_model(robot)
    data = np.load(out)
    hinges = hinge_names(model)
    assert list(data["joint_names"]) == hinges
    assert list(data["body_names"]) == [model.body(i).name for i in range(1, model.nbody)]
    lacking = [i for i, name in enumerate(hinges) if name not in robot.config.joint_names]
    if robot_name == "g1":
        assert (len(hinges), model.nbody - 1, len(lacking)) == (29, 30, 6)
        assert "written as 0: waist_roll_joint, waist_pitch_joint, left_wrist_pitch_joint" in result.stderr
        assert list(offsets) == ["torso_link"]
    else:
        assert (model.nq, lacking, offsets) == (robot.model.nq, [], {})
    assert not data["joint_pos"][:, lacking].any()
    duration = {"g1": 131.5, "h1_2": 225.7}[robot_name]
    frames = round(duration * (fps or 50.0))
    assert float(data["fps"][0]) == (fps or 50.0)
    assert data["joint_pos"].shape == data["joint_vel"].shape == (frames, len(hinges))
    for key in ("body_pos_w", "body_lin_vel_w", "body_ang_vel_w"):
        assert data[key].shape == (frames, model.nbody - 1, 3)
    assert data["body_quat_w"].shape == (frames, model.nbody - 1, 4)
    state = mujoco.MjData(model)
    for t in np.linspace(0, frames - 1, 7).astype(int):
        state.qpos[:3] = data["body_pos_w"][t, 0]
        state.qpos[3:7] = data["body_quat_w"][t, 0]
        for name, angle in zip(hinges, data["joint_pos"][t]):
            state.qpos[model.jnt_qposadr[model.joint(name).id]] = angle
        mujoco.mj_kinematics(model, state)
        expected = state.xpos[1:].copy()
        for body, offset in offsets.items():
            index = model.body(body).id
            expected[index - 1] += state.xmat[index].reshape(3, 3) @ offset
        np.testing.assert_allclose(expected, data["body_pos_w"][t], atol=1e-5)
        np.testing.assert_allclose(np.abs(np.sum(state.xquat[1:] * data["body_quat_w"][t], axis=-1)), 1.0, atol=1e-5)
    if robot_name == "g1":
        torso = model.body("torso_link").id
        assert np.linalg.norm(expected[torso - 1] - state.xpos[torso]) == pytest.approx(0.010)
    # Velocities are those of the positions: finite differences over one frame.
    dt = 1.0 / (fps or 50.0)
    moved = (data["body_pos_w"][2:] - data["body_pos_w"][:-2]) / (2 * dt)
    assert np.median(np.abs(moved - data["body_lin_vel_w"][1:-1])) < 1e-3


@pytest.mark.slow
@pytest.mark.parametrize(
    ("robot_name", "motion", "source", "made_by"),
    [
        ("g1", "dance1_subject2", "bvh", "retarget"),
        ("h1", "dance2_subject3", "csv", "import"),
        ("h1_2", "dance2_subject4", "csv", "import"),
    ],
)
def test_every_robot_exports_both_formats(
    robot_name: str,
    motion: str,
    source: str,
    made_by: str,
    artifacts: Path,
    tmp_path: Path,
    reference_seeds: ReferenceSeeds,
) -> None:
    if source == "bvh":  # the retargeted take, made once for the session
        reference_seeds.into(artifacts, robot_name, motion)
    robot = load_robot(robot_name)
    for fmt, suffix in (("csv", "csv"), ("mjlab", "npz")):
        out = tmp_path / f"{robot_name}.{suffix}"
        result = cli(
            "export-motion",
            "--robot",
            robot_name,
            "--motion",
            motion,
            "--source",
            source,
            "--format",
            fmt,
            "--out",
            str(out),
        )
        assert result.returncode == 0, result.stderr
        assert f"from {made_by} " in result.stderr
    columns = np.loadtxt(tmp_path / f"{robot_name}.csv", delimiter=",").shape[1]
    assert columns == 7 + len(robot.config.csv_joints)
    task_joints = hinge_names(task_model(robot)[0])
    assert np.load(tmp_path / f"{robot_name}.npz")["joint_pos"].shape[1] == len(task_joints)


@pytest.mark.slow
def test_g1_29dof_runs_the_dag_and_its_mjlab_export_moves_waist_and_wrists(artifacts: Path, tmp_path: Path) -> None:
    """The 29-DoF G1 is only a robot config and its model: the smoke DAG runs, and its mjlab npz
    carries the waist roll/pitch and wrist pitch/yaw angles the 23-DoF G1 writes as 0."""
    take = ("--robot", "g1_29dof", "--motion", "dance1_subject2", "--profile", "smoke")
    run = cli("run", *take, "--set", "validate.render.enabled=false")
    assert run.returncode == 0, run.stderr
    (validate,) = (artifacts / "validate" / "g1_29dof" / "dance1_subject2").iterdir()
    assert (validate / "report.json").is_file()
    out = tmp_path / "g1_29dof.npz"
    exported = cli(
        "export-motion", "--robot", "g1_29dof", "--motion", "dance1_subject2", "--format", "mjlab", "--out", str(out)
    )
    assert exported.returncode == 0, exported.stderr
    assert "lacks" not in exported.stderr
    with np.load(out) as motion:
        names = list(motion["joint_names"])
        for joint in ("waist_roll_joint", "waist_pitch_joint", "left_wrist_pitch_joint", "right_wrist_yaw_joint"):
            assert np.abs(motion["joint_pos"][:, names.index(joint)]).max() > 0.1, joint
