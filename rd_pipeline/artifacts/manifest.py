"""What an artifact says of itself: what made it, from what, when, its metrics and the size and
sha256 of each of its files, written last so an artifact without one is never complete."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
from datetime import UTC, datetime
from functools import lru_cache
from pathlib import Path
from typing import Any

from rd_pipeline import __version__, paths
from rd_pipeline.artifacts.plan import PlannedStage
from rd_pipeline.artifacts.store import MANIFEST
from rd_pipeline.files import file_sha256


def artifact_manifest(
    entry: PlannedStage, robot: str | None, motion: str, seconds: float, metrics: dict[str, Any], out: Path
) -> dict[str, Any]:
    """What an artifact says of itself: what made it, from what, when, its metrics and its files' hashes."""
    return {
        "stage": entry.stage.name,
        "key": entry.key,
        "robot": robot,
        "motion": motion,
        "params": dataclasses.asdict(entry.params),
        "inputs": {str(path): entry.input_hashes[label] for label, path in entry.inputs.items()},
        "upstream": entry.upstream,
        "code_version": code_version(),
        "created_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "duration_s": round(seconds, 3),
        "metrics": metrics,
        "files": file_records(out),
    }


def write_manifest(folder: Path, manifest: dict[str, Any]) -> None:
    """Write the manifest through a temporary file so it is never seen half-written."""
    temp = folder / f"{MANIFEST}.partial"
    temp.write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    os.replace(temp, folder / MANIFEST)


def file_records(folder: Path) -> dict[str, dict[str, Any]]:
    """Size and sha256 of every file under `folder` (the manifest excepted), by relative path."""
    records = {}
    for path in sorted(p for p in folder.rglob("*") if p.is_file() and p.name != MANIFEST):
        records[str(path.relative_to(folder))] = {"size": path.stat().st_size, "sha256": file_sha256(path)}
    return records


@lru_cache(maxsize=1)
def code_version() -> str:
    """`0.1.0+g<commit>` in a git checkout, else the package version."""
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=paths.PROJECT_ROOT,
            capture_output=True,
            text=True,
            timeout=5,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    return f"{__version__}+g{commit}" if commit else __version__
