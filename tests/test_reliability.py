"""Concurrent runs on one store, damaged artifacts: what issue 15 found broken, reproduced."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import LAFAN_DIR, PROJECT, RETARGETED_DIR, ROBOT_ASSETS, cli

from rd_pipeline.errors import PipelineError
from rd_pipeline.motion.reference import ReferenceMotion
from rd_pipeline.training.config import clip_frames
from rd_pipeline.training.log import read_training_log

CSV_RUN = ("run", "--robot", "h1_2", "--motion", "dance2_subject4", "--until", "stats")


def _states(robot: str, motion: str, *extra: str) -> dict[str, dict]:
    status = json.loads(cli("status", "--robot", robot, "--motion", motion, "--json", *extra).stdout)
    return {row["stage"]: row for row in status["pipelines"][0]["stages"]}


@pytest.mark.slow
@pytest.mark.usefixtures("g1_dance_store")
def test_two_runs_of_one_key_started_together_both_succeed(artifacts: Path) -> None:
    args = [
        sys.executable,
        "-m",
        "rd_pipeline",
        "run",
        "--robot",
        "g1",
        "--motion",
        "dance1_subject2",
        "--until",
        "train",
        "--clip",
        "0:4",
        "--set",
        "train.iterations=4",
        "train.checkpoint_every=2",
    ]
    runs = [
        subprocess.Popen(args, cwd=PROJECT, env=os.environ.copy(), stderr=subprocess.PIPE, text=True) for _ in range(2)
    ]
    errors = [run.communicate(timeout=600)[1] for run in runs]
    assert [run.returncode for run in runs] == [0, 0], errors
    train = artifacts / "train" / "g1" / "dance1_subject2"
    (key,) = list(train.iterdir())  # one artifact, no work, temporary or lock entries left behind
    assert [row["iteration"] for row in read_training_log(key)] == [1, 2, 3, 4]
    # One run did the training, the other waited for it and took its artifact.
    assert sum("run    train" in e for e in errors) == 1
    assert sum("cached train" in e for e in errors) == 1
    leftovers = [p for p in artifacts.rglob(".*") if p.name.startswith((".work-", ".tmp-", ".lock-"))]
    assert leftovers == []
    # Piped, progress is plain lines (no blank lines left by a live display), and a summary ends the run.
    trainer = next(e for e in errors if "run    train" in e)
    assert "" not in trainer.splitlines()
    assert "  PPO g1: 4/4 (" in trainer
    summary = trainer[trainer.index("summary g1/dance1_subject2, profile smoke:") :].splitlines()
    stages = [line for line in summary[1:] if line.startswith("  ")]
    assert [line.split()[0] for line in stages] == ["parse", "retarget", "stats", "prior", "train"]
    assert stages[-1].split()[1] == "ran"  # the other run may have computed the upstream stages
    assert "iterations=4" in stages[-1]
    # The note counts the iterations that ran, not the profile's 2.
    assert summary[-1].startswith("note: smoke is a plumbing check: 4 iterations train no policy")


@pytest.mark.slow
def test_a_truncated_artifact_is_reported_and_recomputed(artifacts: Path) -> None:
    assert cli(*CSV_RUN).returncode == 0
    (folder,) = list((artifacts / "import" / "h1_2" / "dance2_subject4").iterdir())
    reference = folder / "reference.npz"
    size = reference.stat().st_size
    reference.write_bytes(reference.read_bytes()[: size // 2])
    state = _states("h1_2", "dance2_subject4")["import"]
    assert state["state"] == "damaged"
    assert state["reason"] == f"reference.npz is {size // 2} bytes, the manifest says {size}"
    rerun = cli(*CSV_RUN)
    assert rerun.returncode == 0, rerun.stderr
    assert f"damaged {folder}: reference.npz is {size // 2} bytes" in " ".join(rerun.stderr.split())
    assert "run    import" in rerun.stderr and "cached stats" in rerun.stderr
    assert reference.stat().st_size == size
    assert _states("h1_2", "dance2_subject4")["import"]["state"] == "cached"


@pytest.mark.slow
def test_a_key_folder_without_its_manifest_is_replaced_by_the_rerun(artifacts: Path) -> None:
    assert cli(*CSV_RUN).returncode == 0
    (folder,) = list((artifacts / "import" / "h1_2" / "dance2_subject4").iterdir())
    (folder / "manifest.json").unlink()
    assert _states("h1_2", "dance2_subject4")["import"]["state"] == "missing"
    rerun = cli(*CSV_RUN)
    assert rerun.returncode == 0, rerun.stderr
    assert "run    import" in rerun.stderr
    assert (folder / "manifest.json").is_file()
    assert _states("h1_2", "dance2_subject4")["import"]["state"] == "cached"


@pytest.mark.slow
def test_a_changed_byte_is_found_by_verify_and_when_a_stage_loads_the_artifact(artifacts: Path) -> None:
    assert cli(*CSV_RUN).returncode == 0
    (folder,) = list((artifacts / "import" / "h1_2" / "dance2_subject4").iterdir())
    reference = folder / "reference.npz"
    data = bytearray(reference.read_bytes())
    data[len(data) // 2] ^= 0xFF
    reference.write_bytes(bytes(data))
    assert _states("h1_2", "dance2_subject4")["import"]["state"] == "cached"  # sizes only
    verified = _states("h1_2", "dance2_subject4", "--verify")["import"]
    assert verified["state"] == "damaged"
    assert verified["reason"] == "reference.npz does not match its sha256 in the manifest"
    for stats in (artifacts / "stats" / "h1_2" / "dance2_subject4").iterdir():
        subprocess.run(["rm", "-r", str(stats)], check=True)
    rerun = cli(*CSV_RUN)  # stats runs again and loads the reference: it is checked, found and recomputed
    assert rerun.returncode == 0, rerun.stderr
    assert "does not match its sha256" in rerun.stderr and "run    import" in rerun.stderr
    assert _states("h1_2", "dance2_subject4", "--verify")["import"]["state"] == "cached"


@pytest.mark.offline
def test_reading_a_damaged_npz_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "reference.npz"
    path.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(PipelineError, match=f"^{path}: cannot be read \\(BadZipFile"):
        ReferenceMotion.load(path)


def test_a_three_frame_bvh_is_refused_by_parse_with_the_minimum(tmp_path: Path) -> None:
    lines = (LAFAN_DIR / "dance1_subject2.bvh").read_text().splitlines()
    header = lines.index("MOTION")
    short = [*lines[: header + 1], "Frames: 3", lines[header + 2], *lines[header + 3 : header + 6]]
    path = tmp_path / "dance1_subject2.bvh"
    path.write_text("\n".join(short) + "\n")
    result = cli(
        "run",
        "--robot",
        "g1",
        "--motion",
        "dance1_subject2",
        "--until",
        "parse",
        env={"RD_LAFAN_DIR": str(tmp_path), "RD_ARTIFACTS": str(tmp_path / "store")},
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert errors == [f"error: {path}: 3 frames at 30 fps is 0.10 s; a motion must last at least 1 s"]


@pytest.mark.parametrize("rows", [2, 3, 29])
def test_a_csv_of_a_few_rows_is_refused_with_the_minimum(rows: int, tmp_path: Path) -> None:
    source = (RETARGETED_DIR / "h1" / "dance1_subject1.csv").read_text().splitlines()
    path = tmp_path / "h1" / "dance1_subject1.csv"
    path.parent.mkdir()
    path.write_text("\n".join(source[:rows]) + "\n")
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
    seconds = f"{rows / 30:.2f}"
    assert f"error: {path}: {rows} frames at 30 fps is {seconds} s; a motion must last at least 1 s" in result.stderr


@pytest.mark.offline
def test_a_clip_past_the_end_is_clamped_and_said() -> None:
    said = []
    assert clip_frames("125:1000", 50.0, 6575, said.append) == (6250, 6575)
    assert said == ["train.clip '125:1000' ends after the 131.50 s motion: training on 125:131.50"]
    with pytest.raises(PipelineError, match=r"^train.clip '131:140' leaves less than 1 s of the 131.50 s motion$"):
        clip_frames("131:140", 50.0, 6575, said.append)


@pytest.mark.parametrize(
    ("clip", "message"),
    [
        ("[/x]", "must be START:END in seconds, got '[/x]'"),
        ("[bold]x", "must be START:END in seconds, got '[bold]x'"),
        ("5:2", "must end more than 1 s after it starts, got '5:2'"),
        ("0:0.1", "must end more than 1 s after it starts, got '0:0.1'"),
        ("-1:5", "must start at 0 s or later, got '-1:5'"),
        ("1:2:3", "must be START:END in seconds, got '1:2:3'"),
    ],
)
def test_a_malformed_clip_is_refused_literally_when_params_are_read(clip: str, message: str, artifacts: Path) -> None:
    result = cli("run", "--until", "parse", "--set", f"train.clip={clip}")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [f"error: parameter 'train.clip' {message}"]
    assert not artifacts.exists()  # refused before any stage ran


def test_a_cached_parse_loads_neither_torch_nor_mujoco(artifacts: Path) -> None:
    """What made a cached `run --until parse` take 3.2 s (`bench/cli_startup.py` times it)."""
    script = (
        "import sys; from rd_pipeline.cli import main; code = main(sys.argv[1:]); "
        "print(code, 'torch._C' in sys.modules, 'mujoco' in sys.modules)"
    )
    args = [sys.executable, "-c", script, "run", "--until", "parse"]
    first = subprocess.run(args, capture_output=True, text=True, cwd=PROJECT, env=os.environ.copy(), check=False)
    assert first.stdout.split()[0] == "0", first.stderr  # computing may load them (scipy probes torch)
    cached = subprocess.run(args, capture_output=True, text=True, cwd=PROJECT, env=os.environ.copy(), check=False)
    assert cached.stdout.split() == ["0", "False", "False"] and "cached parse" in cached.stderr


@pytest.mark.offline
def test_quickstart_without_data_says_in_one_line_how_to_get_it(tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    env = {
        **os.environ,
        "SKIP_INSTALL": "1",
        "RD_LAFAN_DIR": str(empty),
        "RD_RETARGETED_DIR": str(empty),
        "RD_ARTIFACTS": str(tmp_path / "store"),
        "RD_LAFAN_URL": f"file://{tmp_path}/no-such-lafan1.zip",
    }
    result = subprocess.run(
        [str(PROJECT / "scripts" / "quickstart.sh")], capture_output=True, text=True, env=env, check=False, timeout=120
    )
    assert result.returncode == 1
    assert result.stdout.splitlines() == [
        "quickstart: data from the RD_* variables",
        "quickstart: no LAFAN1 data found; downloading it (rd-pipeline fetch-lafan)",
    ]
    last = result.stderr.splitlines()[-1]
    assert last.startswith("quickstart: no motion data: run `.venv/bin/rd-pipeline fetch-lafan`")
    assert "RD_LAFAN_DIR" in last and "RD_RETARGETED_DIR" in last and "RD_ROBOT_ASSETS" in last
    assert "Traceback" not in result.stderr


@pytest.mark.slow
def test_user_text_is_printed_literally(tmp_path: Path) -> None:
    """Paths, names and file:line positions are neither rich markup nor emoji codes."""
    store = tmp_path / "a[bold]b"
    header = cli("run", "--until", "parse", env={"RD_ARTIFACTS": str(store)})
    assert header.returncode == 0, header.stderr
    assert f"artifacts in {store}" in header.stderr
    rows = (RETARGETED_DIR / "h1" / "dance1_subject1.csv").read_text().splitlines()
    fields = rows[99].split(",")
    fields[3:7] = ["0", "0", "0", "0"]  # line 100: a root quaternion of norm 0
    rows[99] = ",".join(fields)
    folder = tmp_path / "csv"
    (folder / "h1").mkdir(parents=True)
    path = folder / "h1" / "dance1_subject1.csv"
    path.write_text("\n".join(rows) + "\n")
    env = {"RD_RETARGETED_DIR": str(folder), "RD_ARTIFACTS": str(tmp_path / "store")}
    result = cli("run", "--robot", "h1", "--motion", "dance1_subject1", "--source", "csv", "--until", "import", env=env)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines()[-1] == f"error: {path}:100: root quaternion has norm 0.000"


@pytest.mark.parametrize("store", ["/sys/rd-store", "file"])
def test_an_unwritable_store_is_one_line_naming_it(store: str, tmp_path: Path) -> None:
    """/sys is mounted read-only; a store below a file cannot be made either."""
    if store == "file":
        (tmp_path / "file").write_text("")
        store = str(tmp_path / "file" / "store")
    for command in (("run", "--until", "parse"), ("view", "--out", str(tmp_path / "g1.rrd"))):
        result = cli(*command, env={"RD_ARTIFACTS": store})
        assert result.returncode == 2, result.stderr
        last = result.stderr.strip().splitlines()[-1]
        assert last.startswith(f"error: cannot write the artifact store {store} (")
        assert last.endswith("); set RD_ARTIFACTS to a writable folder")
        assert "Traceback" not in result.stderr


@pytest.mark.slow
def test_a_cached_run_checks_the_hashes_it_reports_and_status_fails_on_damage(artifacts: Path) -> None:
    until_import = ("run", "--robot", "h1_2", "--motion", "dance2_subject4", "--until", "import")
    assert cli(*until_import).returncode == 0
    (folder,) = list((artifacts / "import" / "h1_2" / "dance2_subject4").iterdir())
    reference = folder / "reference.npz"
    data = bytearray(reference.read_bytes())
    data[len(data) // 2] ^= 0xFF
    reference.write_bytes(bytes(data))
    status = ("status", "--robot", "h1_2", "--motion", "dance2_subject4")
    assert cli(*status).returncode == 0  # sizes only: the flipped byte is not seen
    verified = cli(*status, "--verify")
    assert verified.returncode == 1 and "damaged" in verified.stdout
    assert cli(*status, "--verify", "--json").returncode == 1
    rerun = cli(*until_import)  # every stage cached: the one it would report is hashed, found, recomputed
    assert rerun.returncode == 0, rerun.stderr
    assert f"damaged {folder}: reference.npz does not match its sha256" in " ".join(rerun.stderr.split())
    assert "run    import" in rerun.stderr
    assert cli(*status, "--verify").returncode == 0


@pytest.mark.slow
def test_the_data_folders_come_from_rd_pipeline_toml_without_variables(tmp_path: Path) -> None:
    """What quickstart records beside the data, the CLI reads in a fresh shell, from any folder below."""
    checkout = tmp_path / "checkout"
    (checkout / "work").mkdir(parents=True)
    (checkout / "rd-pipeline.toml").write_text(
        f'[data]\nlafan_dir = "{LAFAN_DIR}"\nretargeted_dir = "{RETARGETED_DIR}"\nrobot_assets = "{ROBOT_ASSETS}"\n'
    )
    env = {k: v for k, v in os.environ.items() if not k.startswith("RD_")}
    listed = subprocess.run(
        [sys.executable, "-m", "rd_pipeline", "motions"], capture_output=True, text=True, cwd=checkout / "work", env=env
    )
    assert listed.returncode == 0, listed.stderr
    assert "dance2_subject4    csv:g1 csv:h1 csv:h1_2" in listed.stdout
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "rd_pipeline",
            "run",
            "--robot",
            "h1_2",
            "--motion",
            "dance2_subject4",
            "--until",
            "import",
        ],
        capture_output=True,
        text=True,
        cwd=checkout / "work",
        env=env,
    )
    assert run.returncode == 0, run.stderr
    assert f"artifacts in {checkout / 'artifacts'}" in run.stderr  # beside the settings file, not in work/
    assert list((checkout / "artifacts" / "import" / "h1_2" / "dance2_subject4").iterdir())
    env["RD_ARTIFACTS"] = str(tmp_path / "elsewhere")  # a variable overrides the file
    again = subprocess.run(
        [sys.executable, "-m", "rd_pipeline", "plan", "--robot", "h1_2", "--motion", "dance2_subject4"],
        capture_output=True,
        text=True,
        cwd=checkout,
        env=env,
    )
    assert f"artifacts in {tmp_path / 'elsewhere'}" in again.stdout


def test_a_clip_beyond_the_motion_is_refused_before_any_stage(artifacts: Path) -> None:
    """The motion's length comes from the BVH header or the CSV's rows, not from running upstream."""
    result = cli("run", "--clip", "500:600")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "error: train.clip '500:600' leaves less than 1 s of the 131.50 s motion"
    ]
    on_csv = cli("run", "--robot", "h1_2", "--motion", "dance2_subject4", "--set", "train.clip=300:310")
    assert on_csv.stderr.strip().splitlines()[-1] == (
        "error: train.clip '300:310' leaves less than 1 s of the 225.70 s motion"
    )
    assert not artifacts.exists()
    assert cli("plan", "--clip", "125:200").returncode == 0  # clamped to the end by train, with a warning


@pytest.mark.parametrize("given", ["absolute", "../relative"])
def test_a_motion_given_as_a_path_is_refused_and_nothing_is_written(
    artifacts: Path, tmp_path: Path, given: str
) -> None:
    """`--motion /…/bvh/dance1_subject2` once wrote its parse artifact into the data folder."""
    take = LAFAN_DIR / "dance1_subject2"
    motion = str(take) if given == "absolute" else os.path.relpath(take, tmp_path)
    before = sorted(LAFAN_DIR.iterdir())
    result = cli("run", "--motion", motion, "--until", "parse", cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        f"error: motion '{motion}' is not a motion name: give a take's name such as dance1_subject2, "
        "not a path (RD_LAFAN_DIR or RD_RETARGETED_DIR say where the files are)"
    ]
    assert sorted(LAFAN_DIR.iterdir()) == before
    assert not artifacts.exists() or not any(artifacts.iterdir())
