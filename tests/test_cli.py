"""Listing commands, help, and fetch-lafan's checksum guard."""

from __future__ import annotations

import json
import os
import sys
import zipfile
from pathlib import Path

import pytest
from conftest import LAFAN_DIR, PROJECT, RETARGETED_DIR, cli

from rd_pipeline.profiles import PROFILES
from rd_pipeline.stages import REGISTRY


@pytest.mark.offline
def test_robots_lists_every_config() -> None:
    result = cli("robots")
    assert result.returncode == 0
    table = {line.split()[0]: line for line in result.stdout.splitlines()}
    assert sorted(table) == sorted(path.stem for path in (PROJECT / "robots").glob("*.toml"))
    assert "27 joints, 21 policy" in table["h1_2"]
    assert "29 joints, 29 policy" in table["g1_29dof"]
    assert len({line.index(" joints") for line in table.values()}) == 1  # one column, whatever the names


def test_motions_lists_sources() -> None:
    result = cli("motions")
    assert result.returncode == 0
    table = {line.split()[0]: line.split()[1:] for line in result.stdout.splitlines()}
    # The expected listing follows from the folders, whatever takes they hold.
    expected: dict[str, list[str]] = {}
    for bvh in sorted(LAFAN_DIR.glob("*.bvh")):
        expected.setdefault(bvh.stem, []).append("bvh")
    for csv in sorted(RETARGETED_DIR.glob("*/*.csv")):
        expected.setdefault(csv.stem, []).append(f"csv:{csv.parent.name}")
    assert table == expected
    # Named takes: a dance with both sources, one with CSVs only, a non-dance take with BVH only.
    assert table["dance1_subject2"] == ["bvh", "csv:g1", "csv:h1", "csv:h1_2"]
    assert table["dance2_subject4"] == ["csv:g1", "csv:h1", "csv:h1_2"]
    assert table["fallAndGetUp1_subject1"] == ["bvh"]


@pytest.mark.offline
@pytest.mark.parametrize("command", ["run", "plan", "stage", "status", "view", "fetch-lafan", "robots", "motions"])
def test_every_subcommand_has_help(command: str) -> None:
    result = cli(command, "--help")
    assert result.returncode == 0 and "usage:" in result.stdout.lower()


def test_ablate_help_lists_the_residual_presets() -> None:
    result = cli("ablate", "--help")
    assert result.returncode == 0, result.stderr
    text = " ".join(result.stdout.split())
    for preset in ("absolute", "selective", "hip_knee_ankle", "all_legs", "legs_torso", "all", "reference_locked"):
        assert preset in text, preset


def test_a_choice_outside_its_literal_is_refused_when_params_are_read(artifacts: Path) -> None:
    result = cli("run", "--until", "parse", "--set", "train.env.actions.mode=half")
    assert result.returncode != 0
    assert result.stderr.strip().splitlines()[-1] == (
        "error: parameter 'train.env.actions.mode' must be one of absolute, selective, hip_knee_ankle, all_legs, "
        "legs_torso, all, reference_locked, got 'half'"
    )
    assert not (artifacts / "parse").exists()  # refused before any stage ran
    take = ("--robot", "h1_2", "--motion", "dance2_subject4")
    result = cli("run", *take, "--until", "import", "--set", "import.interpolation=quadratic")
    assert result.returncode != 0
    assert result.stderr.strip().splitlines()[-1] == (
        "error: parameter 'import.interpolation' must be one of cubic, linear, got 'quadratic'"
    )
    assert not (artifacts / "import").exists()


@pytest.mark.slow
def test_a_qp_solver_that_is_not_installed_is_one_line(artifacts: Path) -> None:
    result = cli("run", "--until", "retarget", "--set", "retarget.ik.solver=osqpx")
    assert result.returncode == 2
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith("error: retarget.ik.solver 'osqpx' is not an installed QP solver (")
    assert "daqp" in last
    assert not (artifacts / "retarget").exists() or not any((artifacts / "retarget").rglob("manifest.json"))


@pytest.mark.parametrize(
    ("assignment", "message"),
    [
        ("train.iterations=0", "parameter 'train.iterations' must be positive, got 0"),
        ("train.iterations=-1", "parameter 'train.iterations' must be positive, got -1"),
        ("train.env.num_envs=0", "parameter 'train.env.num_envs' must be positive, got 0"),
        ("retarget.fps=-50", "parameter 'retarget.fps' must be positive, got -50.0"),
        ("train.seed=1.5", "parameter 'train.seed' must be an integer, got '1.5'"),
        ("train.ppo.gamma=1.5", "parameter 'train.ppo.gamma' must be at most 1, got 1.5"),
        (
            "import.contact.ground_percentile=101",
            "parameter 'import.contact.ground_percentile' must be at most 100, got 101.0",
        ),
        (
            "train.env.rewards.body_pos.sigma=0",
            "parameter 'train.env.rewards.body_pos.sigma' must be positive, got 0.0",
        ),
        (
            "train.env.rewards.torque.weight=0.5",
            "parameter 'train.env.rewards.torque.weight' must be at most 0 like its default, got 0.5",
        ),
        (
            "retarget.weights.feet_position=-1",
            "parameter 'retarget.weights.feet_position' must be at least 0, got -1.0",
        ),
        ("train.ppo.lam=nan", "parameter 'train.ppo.lam' must be finite, got nan"),
        (
            "train.env.randomization.mass_factor=-1,1",
            "parameter 'train.env.randomization.mass_factor' must be at least 0, got -1.0",
        ),
        ("validate.protocol.grid_s=0", "parameter 'validate.protocol.grid_s' must be positive, got 0.0"),
        ("parse.length_unit_m=0", "parameter 'parse.length_unit_m' must be positive, got 0.0"),
        (
            "retarget.repair.guide_costs=1,0",
            "parameter 'retarget.repair.guide_costs' must be one or more positive costs, got (1.0, 0.0)",
        ),
        ("train.sampler.update_interval=0", "parameter 'train.sampler.update_interval' must be positive, got 0"),
        ("train.sampler.cap_factor=0.5", "parameter 'train.sampler.cap_factor' must be at least 1, got 0.5"),
    ],
)
def test_out_of_range_params_are_one_line_naming_the_parameter(assignment: str, message: str, artifacts: Path) -> None:
    result = cli("run", "--until", "parse", "--set", assignment)
    assert result.returncode != 0
    assert result.stderr.strip().splitlines()[-1] == f"error: {message}"
    assert not (artifacts / "parse").exists()


def test_a_ranking_beside_a_chosen_checkpoint_is_refused(artifacts: Path) -> None:
    """It would change nothing but the key: a second artifact of the same export."""
    result = cli("run", "--until", "parse", "--set", "export.checkpoint=400", "export.best_by=completion")
    assert result.returncode != 0
    assert result.stderr.strip().splitlines()[-1] == (
        "error: parameter 'export.best_by' ranks checkpoints only when checkpoint is 0, got checkpoint 400 (drop one of the two)"
    )
    assert not (artifacts / "parse").exists()


@pytest.mark.offline
def test_fetch_lafan_rejects_a_wrong_archive(tmp_path: Path) -> None:
    archive = tmp_path / "lafan1.zip"
    with zipfile.ZipFile(archive, "w") as handle:
        handle.writestr("dance1_subject1.bvh", "HIERARCHY\n")
    target = tmp_path / "raw"
    result = cli("fetch-lafan", "--zip", str(archive), env={"RD_LAFAN_DIR": str(target)})
    assert result.returncode == 2
    assert f"error: {archive}: sha256 " in result.stderr and "is not the official lafan1.zip" in result.stderr
    assert not target.exists()


@pytest.mark.offline
def test_run_help_names_every_stage_and_profile() -> None:
    text = " ".join(cli("run", "--help").stdout.split())
    for name in [stage.name for stage in REGISTRY] + list(PROFILES):
        assert name in text, name


def test_plan_shows_each_stage_with_the_params_file_merged_into_the_profile(tmp_path: Path, artifacts: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text("stages:\n  train:\n    env:\n      num_envs: 64\n")
    assert cli("run", "--until", "parse").returncode == 0
    result = cli("plan", "--profile", "paper", "--params-file", str(params), "--json")
    assert result.returncode == 0, result.stderr
    rows = json.loads(result.stdout)
    assert [row["stage"] for row in rows] == ["parse", "retarget", "stats", "prior", "train", "export", "validate"]
    assert [row["cached"] for row in rows] == [True] + [False] * 6
    train = rows[4]["params"]
    # The file names only num_envs; the profile's other train.env fields stay.
    assert (train["env"]["num_envs"], train["env"]["backend"], train["env"]["device"]) == (64, "warp", "cuda")
    assert train["iterations"] == 20000
    assert sorted(path.name for path in artifacts.iterdir()) == ["parse"]  # plan ran nothing


def test_a_params_file_and_set_give_the_same_keys(tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text("stages:\n  train:\n    env:\n      num_envs: 64\n")
    from_file = json.loads(cli("plan", "--profile", "paper", "--params-file", str(params), "--json").stdout)
    from_set = json.loads(cli("plan", "--profile", "paper", "--set", "train.env.num_envs=64", "--json").stdout)
    assert [row["key"] for row in from_file] == [row["key"] for row in from_set]
    default = json.loads(cli("plan", "--profile", "paper", "--json").stdout)
    assert default[4]["key"] != from_set[4]["key"]  # the value reached the key


def test_a_control_rate_off_the_reference_fps_is_refused_before_any_stage(artifacts: Path) -> None:
    result = cli("run", "--set", "train.env.decimation=4")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines()[-1] == (
        "error: train.env.physics_dt * train.env.decimation give a 125 Hz control rate, but retarget.fps is 50: "
        "the policy steps once per reference frame"
    )
    assert not artifacts.exists()
    agreeing = cli("plan", "--set", "train.env.decimation=4", "retarget.fps=125")
    assert agreeing.returncode == 0, agreeing.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("stage", "train", "--motion", "dance1_subject2"), "error: stage 'train' needs --robot"),
        (
            ("stage", "parse", "--motion", "dance1_subject2", "--source", "csv"),
            "error: stage 'parse' reads the bvh source, not --source csv",
        ),
        (
            ("run", "--only", "train", "--until", "export"),
            "error: --only runs one stage; it cannot be combined with --until",
        ),
        (("status", "--robot", "g9"), "error: unknown robot 'g9'"),
    ],
)
def test_misused_options_name_what_is_wrong(args: tuple[str, ...], message: str, artifacts: Path) -> None:
    result = cli(*args)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines()[-1].startswith(message)
    assert not artifacts.exists()


@pytest.mark.slow  # trains and validates a window: an end-to-end run
def test_window_trains_on_the_stretch_the_reference_speed_chooses(artifacts: Path) -> None:
    """H1-2 dance2_subject4 (225.7 s of dataset CSV): its typical ten seconds and its busiest,
    read from the imported reference; the plan is the one `--clip` gives for the same seconds."""
    take = ("--robot", "h1_2", "--motion", "dance2_subject4")
    made = cli("run", *take, "--window", "10", "--until", "import")
    assert made.returncode == 0, made.stderr
    window = "window: 107:117 s at speed quantile 0.5 (joint speed p95 5.248 rad/s; "
    footing = "lowest-foot tilt 3-12 deg by the second, a foot planted in 48% of frames)"
    assert window + footing in made.stderr
    busiest = cli("plan", *take, "--window", "10", "--window-speed", "1", "--json")
    assert busiest.returncode == 0, busiest.stderr
    window = "window: 193:203 s at speed quantile 1 (joint speed p95 7.731 rad/s; "
    footing = "lowest-foot tilt 13-25 deg by the second, a foot planted in 14% of frames)"
    assert window + footing in busiest.stderr
    clipped = cli("plan", *take, "--clip", "193:203", "--json")
    whole = cli("plan", *take, "--json")
    by_window = {row["stage"]: row["key"] for row in json.loads(busiest.stdout)}
    by_clip = {row["stage"]: row["key"] for row in json.loads(clipped.stdout)}
    by_whole = {row["stage"]: row["key"] for row in json.loads(whole.stdout)}
    assert by_window == by_clip
    assert by_window["import"] == by_whole["import"] and by_window["train"] != by_whole["train"]
    # status reports on the run the same options make: the window's import is cached, its train key is the clip's.
    status = cli("status", *take, "--window", "10", "--window-speed", "1", "--json")
    assert status.returncode == 0, status.stderr
    (pipeline,) = json.loads(status.stdout)["pipelines"]
    assert {row["stage"]: row["key"] for row in pipeline["stages"]} == by_clip
    assert {row["stage"]: row["state"] for row in pipeline["stages"]} == {
        "import": "cached",
        "stats": "missing",
        "prior": "missing",
        "train": "missing",
        "export": "missing",
        "validate": "missing",
    }
    # stage takes the same options: one training iteration on the busiest window lands under the clip's key.
    early = cli("stage", "train", *take, "--window", "10", "--window-speed", "1")
    assert early.returncode == 2
    assert early.stderr.strip().splitlines()[-1] == (
        f"error: upstream stage 'stats' has no usable artifact {by_clip['stats']} for h1_2/dance2_subject4; "
        "make it first: `rd-pipeline stage stats` with the same options, or a run through it"
    )
    for upstream in ("stats", "prior"):
        assert cli("stage", upstream, *take).returncode == 0
    one = ("--set", "train.iterations=1")
    trained = cli("stage", "train", *take, "--window", "10", "--window-speed", "1", *one)
    assert trained.returncode == 0, trained.stderr
    clipped_one = cli("plan", *take, "--clip", "193:203", *one, "--json")
    key = {row["stage"]: row["key"] for row in json.loads(clipped_one.stdout)}["train"]
    assert (artifacts / "train" / "h1_2" / "dance2_subject4" / key / "manifest.json").is_file()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ("plan", "--window", "10"),
            "error: window of g1/dance1_subject2: chosen from the reference, which stage 'retarget' has not made yet",
        ),
        (
            ("run", "--window", "10", "--clip", "0:10"),
            "error: --window 10 and train.clip=0:10 both choose the clip: give one",
        ),
        (
            ("run", "--window", "10", "--window-speed", "1.5"),
            "error: window of g1/dance1_subject2: speed quantile 1.5 is outside [0, 1]",
        ),
        (("run", "--window", "0"), "error: window of g1/dance1_subject2: must last 1 s or more, got 0 s"),
        (
            ("run", "--window", "132"),
            "error: window of g1/dance1_subject2: a 132 s window does not fit the 131.5 s take",
        ),
        (("run", "--window-speed", "1"), "error: --window-speed 1 chooses among windows: give --window too"),
        (
            ("status", "--window", "10"),
            "error: --window 10 is chosen from one take's reference: give --robot and --motion",
        ),
        (
            ("run", "--window", "10", "--from", "train"),
            "error: window of g1/dance1_subject2: chosen from the reference, which stage 'retarget' has not made yet",
        ),
        (
            ("run", "--window", "10", "--only", "trian"),
            "error: --only: unknown stage 'trian' (stages: parse, retarget, import, stats, prior, train, export, validate)",
        ),
    ],
)
def test_a_window_that_cannot_be_chosen_is_one_line_before_any_stage(
    args: tuple[str, ...], message: str, artifacts: Path
) -> None:
    result = cli(*args)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines()[-1] == message
    assert not artifacts.exists()


@pytest.mark.offline
def test_help_to_a_reader_that_left_ends_quietly(monkeypatch: pytest.MonkeyPatch) -> None:
    """`rd-pipeline run --help | head -1`: the help meets a closed pipe while tyro prints it."""
    from rd_pipeline.cli.app import main

    read, write = os.pipe()
    os.close(read)
    with os.fdopen(write, "w", buffering=1) as closed:  # each line reaches the pipe, as help does
        monkeypatch.setattr(sys, "stdout", closed)
        assert main(["run", "--help"]) == 0


def test_a_window_beside_a_params_file_clip_is_refused(tmp_path: Path, artifacts: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text('stages:\n  train:\n    clip: "3:14"\n')
    result = cli("run", "--window", "10", "--params-file", str(params))
    assert result.returncode == 2
    assert (
        result.stderr.strip().splitlines()[-1]
        == "error: --window 10 and train.clip=3:14 both choose the clip: give one"
    )
    assert not artifacts.exists()
