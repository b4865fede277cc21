"""Profiles: named sets of stage parameters (data, not code branches).

`smoke` runs in seconds (CI), `cpu` on a workstation in hours, `paper` on one GPU with the
appendix settings. Each is a TOML file here with one table per stage; a stage absent from a
profile uses its params dataclass defaults.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from rd_pipeline.errors import PipelineError

PROFILE_DIR = Path(__file__).parent
PROFILES = tuple(sorted(p.stem for p in PROFILE_DIR.glob("*.toml")))


def load_profile(name: str) -> dict[str, dict[str, Any]]:
    """The profile's stage tables (its `[profile]` table, about the profile itself, left out)."""
    tables = _read(name)
    tables.pop("profile", None)
    return tables


def profile_note(name: str) -> str | None:
    """What a user should know about results of this profile (`[profile] note`), if anything."""
    return _read(name).get("profile", {}).get("note")


def _read(name: str) -> dict[str, Any]:
    path = PROFILE_DIR / f"{name}.toml"
    if not path.is_file():
        raise PipelineError(f"unknown profile '{name}' (profiles: {', '.join(PROFILES)})")
    return tomllib.loads(path.read_text())
