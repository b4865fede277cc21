"""`pip install .` (not editable) gives a package that runs from any directory and installs nothing
generically named: `stages/` and `robots/*.toml` go inside `rd_pipeline`."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import PROJECT


@pytest.mark.slow
def test_a_plain_install_runs_from_another_directory(tmp_path: Path) -> None:
    site = tmp_path / "site"
    install = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--no-deps",
            "--no-build-isolation",
            "--target",
            str(site),
            str(PROJECT),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert install.returncode == 0, install.stderr
    assert "Warning" not in install.stderr and "deprecated" not in install.stderr, install.stderr
    top = sorted(p.name for p in site.iterdir())
    assert top[:1] == ["bin"] and top[1] == "rd_pipeline" and top[2].startswith("rd_pipeline-") and len(top) == 3
    installed = sorted(p.name for p in (site / "rd_pipeline" / "robot_configs").glob("*.toml"))
    assert installed == sorted(p.name for p in (PROJECT / "robots").glob("*.toml"))  # every shipped robot
    assert (site / "rd_pipeline" / "robot_configs" / "interop" / "mjlab.toml").is_file()
    script = "import sys, rd_pipeline; from rd_pipeline.cli import main; print(rd_pipeline.__file__); sys.exit(main(sys.argv[1:]))"
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {**os.environ, "PYTHONPATH": str(site), "RD_ARTIFACTS": str(tmp_path / "store")}
    run = subprocess.run(
        [sys.executable, "-c", script, "run", "--robot", "h1", "--motion", "dance2_subject3", "--until", "import"],
        capture_output=True,
        text=True,
        cwd=elsewhere,
        env=env,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == str(site / "rd_pipeline" / "__init__.py")
    assert "done   import" in run.stderr
