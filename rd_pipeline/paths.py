"""Where data and artifacts live, resolved from the SPEC's environment variables."""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

from rd_pipeline import robot_configs  # type: ignore[attr-defined]  # mapped from robots/ by setuptools
from rd_pipeline.errors import PipelineError, nearest

PROJECT_ROOT = Path(__file__).resolve().parent.parent
"""The checkout holding the package (in an installed copy: site-packages). Data paths are relative
to the working directory, as DVC runs commands from the project root."""

ROBOT_CONFIG_DIR = Path(robot_configs.__file__).parent
"""The robots' TOML configurations: `robots/` of the checkout, installed as `rd_pipeline.robot_configs`."""


SETTINGS_FILE = "rd-pipeline.toml"
"""Where a checkout records its data folders (`[data]`: `lafan_dir`, `retargeted_dir`,
`robot_assets`, `robot_configs`, `artifacts`); found in the working directory or the nearest folder above it.
`scripts/quickstart.sh` writes one when it finds the data; the `RD_*` variables override it."""


def settings_file() -> Path | None:
    """The nearest `rd-pipeline.toml` at or above the working directory."""
    here = Path.cwd()
    for folder in (here, *here.parents):
        if (folder / SETTINGS_FILE).is_file():
            return folder / SETTINGS_FILE
    return None


DATA_KEYS = ("lafan_dir", "retargeted_dir", "robot_assets", "robot_configs", "artifacts")
"""The keys of the settings file's one table, `[data]`."""


def _data_settings(path: Path) -> dict[str, str]:
    try:
        settings = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise PipelineError(f"{path}: cannot be read ({exc})") from None
    for name in settings:
        if name != "data":
            raise PipelineError(f"{path}: unknown table [{name}]{nearest(name, ['data'])}; the file has one, [data]")
    data = settings.get("data", {})
    if not isinstance(data, dict) or not all(isinstance(v, str) for v in data.values()):
        raise PipelineError(f"{path}: [data] must map names to folder paths")
    for key in data:
        if key not in DATA_KEYS:
            raise PipelineError(
                f"{path}: unknown key '{key}' in [data]{nearest(key, DATA_KEYS)} (keys: {', '.join(DATA_KEYS)})"
            )
    return data


def _folder(variable: str, key: str, default: str | None, existing: bool = True) -> Path | None:
    """`variable` when set, else `key` of the settings file (relative to it), else `default` beside
    the settings file or, without one, in the working directory. A folder the variable or the key
    names must exist (unless not `existing`: one about to be made)."""
    value = os.environ.get(variable)
    if value:
        path = Path(value).expanduser().resolve()
        if existing and not path.is_dir():
            raise PipelineError(f"{variable}={value}: no such folder")
        return path
    settings = settings_file()
    base = settings.parent if settings else Path.cwd()
    if settings is not None:
        data = _data_settings(settings)
        if key in data:
            path = (base / Path(data[key]).expanduser()).resolve()
            if existing and not path.is_dir():
                raise PipelineError(f'{settings}: [data] {key} = "{data[key]}" names {path}, which is not a folder')
            return path
    return None if default is None else base / default


def lafan_dir(existing: bool = True) -> Path:
    """Folder of raw LAFAN1 BVH files (`RD_LAFAN_DIR`, else `lafan_dir` of `rd-pipeline.toml`, else
    `raw_lafan/`); not `existing`: where `fetch-lafan` is to put them."""
    return _folder("RD_LAFAN_DIR", "lafan_dir", "raw_lafan", existing)  # type: ignore[return-value]


def retargeted_dir() -> Path | None:
    """Folder of LAFAN1_Retargeting_Dataset CSVs laid out `<robot>/<motion>.csv` (`RD_RETARGETED_DIR`,
    else `retargeted_dir` of `rd-pipeline.toml`)."""
    return _folder("RD_RETARGETED_DIR", "retargeted_dir", None)


def robot_assets_dir() -> Path | None:
    """A folder laid out like unitree_ros `robots/` (`RD_ROBOT_ASSETS`, else `robot_assets` of
    `rd-pipeline.toml`); None: the `robot_descriptions` clone."""
    return _folder("RD_ROBOT_ASSETS", "robot_assets", None)


def robot_configs_dir() -> Path | None:
    """A folder of robot TOMLs of the user's own (`RD_ROBOT_CONFIGS`, else `robot_configs` of
    `rd-pipeline.toml`); a name there takes precedence over the configs shipped in `robots/`."""
    return _folder("RD_ROBOT_CONFIGS", "robot_configs", None)


def artifacts_dir() -> Path:
    """Root of the content-addressed artifact store (`RD_ARTIFACTS`, else `artifacts` of
    `rd-pipeline.toml`, else `artifacts/`)."""
    return _folder("RD_ARTIFACTS", "artifacts", "artifacts", existing=False)  # type: ignore[return-value]


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
