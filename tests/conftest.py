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
ROBOT_ASSETS = Path(os.environ["RD_ROBOT_ASSETS"])
MISSING_DATA = [str(p) for p in (LAFAN_DIR, RETARGETED_DIR, ROBOT_ASSETS) if not p.is_dir()]


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Without the real data every test that reads it is skipped, saying which folder is missing."""
    if not MISSING_DATA:
        return
    reason = (
        f"needs the shared data, missing: {', '.join(MISSING_DATA)} "
        "(set RD_LAFAN_DIR, RD_RETARGETED_DIR and RD_ROBOT_ASSETS, or put the data in ../shared)"
    )
    for item in items:
        if "offline" not in item.keywords:
            item.add_marker(pytest.mark.skip(reason=reason))


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
