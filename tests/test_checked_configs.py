"""Every file a user writes is checked key by key: a misspelt key or table, a folder that is not
there, a skeleton that is not LAFAN1's, an extra that is not installed: one line naming it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import RETARGETED_DIR, ROBOT_ASSETS, cli

from rd_pipeline.motion.lafan import LAFAN_JOINTS
from rd_pipeline.paths import ROBOT_CONFIG_DIR

IMPORT = ("run", "--robot", "h1_2", "--motion", "dance2_subject4", "--until", "import")


def _last_line(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    return result.stderr.strip().splitlines()[-1]


def _in_checkout(checkout: Path, settings: str, *args: str) -> subprocess.CompletedProcess:
    """`rd-pipeline` run in `checkout` with only its `rd-pipeline.toml` to say where data is."""
    checkout.mkdir(exist_ok=True)
    (checkout / "rd-pipeline.toml").write_text(settings)
    env = {k: v for k, v in os.environ.items() if not k.startswith("RD_")}
    return subprocess.run(
        [sys.executable, "-m", "rd_pipeline", *args], capture_output=True, text=True, cwd=checkout, env=env
    )


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ('[data]\nlafan_dirr = "bvh"\n', "unknown key 'lafan_dirr' in [data] (did you mean 'lafan_dir'?)"),
        ('[dta]\nlafan_dir = "bvh"\n', "unknown table [dta] (did you mean 'data'?); the file has one, [data]"),
        ('[data]\nlafan_dir = "no/such/bvh"\n', '[data] lafan_dir = "no/such/bvh" names {checkout}/no/such/bvh'),
    ],
)
def test_rd_pipeline_toml_is_checked_key_by_key(settings: str, message: str, tmp_path: Path) -> None:
    checkout = tmp_path / "checkout"
    settings += f'retargeted_dir = "{RETARGETED_DIR}"\n' if settings.startswith("[data]") else ""
    last = _last_line(_in_checkout(checkout, settings, *IMPORT))
    assert last.startswith(f"error: {checkout / 'rd-pipeline.toml'}: {message.format(checkout=checkout)}"), last
    assert not (checkout / "artifacts").exists()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("profile: smoke\n", "a params file sets params under a 'stages:' table, and this one has none"),
        (
            "stagez:\n  train:\n    seed: 3\n",
            "a params file sets params under a 'stages:' table, and this one has none ('stagez' is spelled like it)",
        ),
        ("stages:\n  trian:\n    seed: 3\n", "stages.trian is not a stage (did you mean 'train'?)"),
    ],
)
def test_a_params_file_without_its_stages_table_is_refused(text: str, message: str, tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text(text)
    last = _last_line(cli("plan", "--params-file", str(params)))
    assert last.startswith(f"error: {params}: {message}"), last


def test_a_misspelt_parameter_names_the_nearest() -> None:
    last = _last_line(cli("plan", "--set", "train.iteration=3"))
    assert last.startswith("error: unknown parameter 'train.iteration' (did you mean 'iterations'?) (known: "), last


def test_robot_configs_naming_a_missing_folder_is_one_line(tmp_path: Path) -> None:
    missing = tmp_path / "no-such-configs"
    for command in (("robots",), ("plan", "--robot", "mybot")):
        last = _last_line(cli(*command, env={"RD_ROBOT_CONFIGS": str(missing)}))
        assert last == f"error: RD_ROBOT_CONFIGS={missing}: no such folder"


def _user_robot(tmp_path: Path, old: str, new: str) -> Path:
    """A copy of the shipped H1 config as the user's `mybot`, with `old` replaced by `new`."""
    configs = tmp_path / "configs"
    configs.mkdir()
    text = (ROBOT_CONFIG_DIR / "h1.toml").read_text().replace('name = "h1"', 'name = "mybot"')
    assert old in text
    path = configs / "mybot.toml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("[joints.kp]", "[joints.kpp]", "unknown key 'kpp' in [joints] (did you mean 'kp'?)"),
        ("[collision]", "[colision]", "unknown key 'colision' at the top (did you mean 'collision'?)"),
        ("[asset]\n", "[asset]\nmjfc = 'x'\n", "unknown key 'mjfc' in [asset] (did you mean 'mjcf'?)"),
    ],
)
def test_a_robot_toml_key_or_table_it_does_not_have_is_refused(
    old: str, new: str, message: str, tmp_path: Path
) -> None:
    path = _user_robot(tmp_path, old, new)
    last = _last_line(cli("plan", "--robot", "mybot", env={"RD_ROBOT_CONFIGS": str(path.parent)}))
    assert last.startswith(f"error: {path}: {message} (keys: "), last


def test_a_missing_mjcf_names_the_toml_and_its_key(tmp_path: Path) -> None:
    path = _user_robot(tmp_path, 'mjcf = "h1_description/', 'mjcf = "no_description/')
    last = _last_line(cli("plan", "--robot", "mybot", env={"RD_ROBOT_CONFIGS": str(path.parent)}))
    missing = ROBOT_ASSETS / "no_description" / "mjcf" / "h1.xml"
    assert last == (
        f"error: {missing}: robot model file not found, named by asset.mjcf of {path} (check RD_ROBOT_ASSETS)"
    )


@pytest.mark.parametrize("frames", [30, 60])
def test_a_bvh_of_another_skeleton_is_refused_at_parse_naming_every_missing_joint(frames: int, tmp_path: Path) -> None:
    header = (
        "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n"
        " JOINT Spine\n {\n  OFFSET 0 10 0\n  CHANNELS 3 Zrotation Yrotation Xrotation\n"
        "  JOINT Head\n  {\n   OFFSET 0 10 0\n   CHANNELS 3 Zrotation Yrotation Xrotation\n"
        "   End Site\n   {\n    OFFSET 0 5 0\n   }\n  }\n }\n}\n"
    )
    motion = f"MOTION\nFrames: {frames}\nFrame Time: 0.033333\n" + "0 90 0 0 0 0 0 0 0 0 0 0\n" * frames
    bvh = tmp_path / "bvh" / "tiny_subject1.bvh"
    bvh.parent.mkdir()
    bvh.write_text(header + motion)
    store = tmp_path / "store"
    env = {"RD_LAFAN_DIR": str(bvh.parent), "RD_ARTIFACTS": str(store)}
    last = _last_line(cli("run", "--robot", "g1", "--motion", "tiny_subject1", "--until", "retarget", env=env))
    missing = [joint for joint in LAFAN_JOINTS if joint not in ("Hips", "Spine", "Head")]
    assert last == f"error: {bvh}: not a LAFAN1 skeleton; it lacks the joints {', '.join(missing)}"
    assert not list(store.rglob("manifest.json"))


def test_a_sweep_on_ray_without_ray_says_so_before_any_work(tmp_path: Path) -> None:
    # A `ray` that cannot be found, as on a machine without the extra.
    shadow = tmp_path / "shadow"
    shadow.mkdir()
    (shadow / "sitecustomize.py").write_text("import sys\nsys.modules['ray'] = None\n")
    store = tmp_path / "store"
    env = {"PYTHONPATH": str(shadow), "RD_ARTIFACTS": str(store)}
    last = _last_line(cli("sweep", "--executor", "ray", "--seeds", "1", "2", env=env))
    assert last == "error: --executor ray: ray is not installed; `pip install -e '.[ray]'` adds it"
    assert not store.exists()
