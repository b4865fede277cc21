"""Where data and artifacts live, resolved from the SPEC's environment variables."""

from __future__ import annotations

import os
from pathlib import Path

from rd_pipeline import robot_configs  # type: ignore[attr-defined]  # mapped from robots/ by setuptools
from rd_pipeline.errors import PipelineError

PROJECT_ROOT = Path(__file__).resolve().parent.parent
"""The checkout holding the package (in an installed copy: site-packages). Data paths are relative
to the working directory, as DVC runs commands from the project root."""

ROBOT_CONFIG_DIR = Path(robot_configs.__file__).parent
"""The robots' TOML configurations: `robots/` of the checkout, installed as `rd_pipeline.robot_configs`."""


def _env_path(name: str, default: Path | None) -> Path | None:
    value = os.environ.get(name)
    return Path(value).expanduser().resolve() if value else default


def lafan_dir() -> Path:
    """Folder of raw LAFAN1 BVH files (`RD_LAFAN_DIR`, default `raw_lafan/` of the working directory)."""
    return _env_path("RD_LAFAN_DIR", Path.cwd() / "raw_lafan")  # type: ignore[return-value]


def retargeted_dir() -> Path | None:
    """Folder of LAFAN1_Retargeting_Dataset CSVs laid out `<robot>/<motion>.csv` (`RD_RETARGETED_DIR`)."""
    return _env_path("RD_RETARGETED_DIR", None)


def artifacts_dir() -> Path:
    """Root of the content-addressed artifact store (`RD_ARTIFACTS`, default `artifacts/` of the working directory)."""
    return _env_path("RD_ARTIFACTS", Path.cwd() / "artifacts")  # type: ignore[return-value]


def bvh_path(motion: str) -> Path:
    return lafan_dir() / f"{motion}.bvh"


def csv_path(robot: str, motion: str) -> Path | None:
    root = retargeted_dir()
    return None if root is None else root / robot / f"{motion}.csv"


def available_motions() -> dict[str, list[str]]:
    """Motion name -> the sources present for it (`bvh`, `csv:<robot>`)."""
    found: dict[str, list[str]] = {}
    if lafan_dir().is_dir():
        for path in sorted(lafan_dir().glob("*.bvh")):
            found.setdefault(path.stem, []).append("bvh")
    root = retargeted_dir()
    if root is not None and root.is_dir():
        for path in sorted(root.glob("*/*.csv")):
            found.setdefault(path.stem, []).append(f"csv:{path.parent.name}")
    return dict(sorted(found.items()))


def require_file(path: Path, what: str) -> Path:
    if not path.is_file():
        raise PipelineError(f"{path}: {what} not found")
    return path
