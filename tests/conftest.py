"""Tests read the real data from ../shared (SPEC); each test gets its own artifact store."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

PROJECT = Path(__file__).resolve().parent.parent
SHARED = PROJECT.parent / "shared"

for variable, default in {
    "RD_LAFAN_DIR": SHARED / "data" / "lafan1" / "bvh",
    "RD_RETARGETED_DIR": SHARED / "data" / "lafan1_retargeted",
    "RD_ROBOT_ASSETS": SHARED / "robots",
}.items():
    os.environ.setdefault(variable, str(default))

LAFAN_DIR = Path(os.environ["RD_LAFAN_DIR"])
RETARGETED_DIR = Path(os.environ["RD_RETARGETED_DIR"])


@pytest.fixture
def artifacts(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    root = tmp_path / "artifacts"
    monkeypatch.setenv("RD_ARTIFACTS", str(root))
    return root


def cli(*args: str, env: dict[str, str] | None = None, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run `rd-pipeline` in a subprocess, as a user would."""
    return subprocess.run(
        [sys.executable, "-m", "rd_pipeline", *args],
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
        cwd=cwd or PROJECT,
        timeout=600,
    )
