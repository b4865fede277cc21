"""Which source a motion is read from: LAFAN1's raw BVH (retargeted here) or a dataset CSV (already
retargeted to the robot)."""

from __future__ import annotations

import re
from pathlib import Path

from rd_pipeline import paths
from rd_pipeline.errors import PipelineError

SOURCES = ("bvh", "csv")
MOTION_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
"""A take's file name without its extension: it names folders of the store, so never a path."""


def check_motion_name(motion: str) -> None:
    """Refuse a motion that is not a plain name (a path would place artifacts outside the store)."""
    if not MOTION_NAME.fullmatch(motion) or ".." in motion:
        raise PipelineError(
            f"motion '{motion}' is not a motion name: give a take's name such as dance1_subject2, "
            "not a path (RD_LAFAN_DIR or RD_RETARGETED_DIR say where the files are)"
        )


def resolve_source(robot: str | None, motion: str, forced: str | None) -> str:
    """`bvh` when the raw BVH exists, else `csv` when the robot's retargeted CSV exists."""
    if forced is not None:
        if forced not in SOURCES:
            raise PipelineError(f"--source must be one of {', '.join(SOURCES)}, got '{forced}'")
        _require_forced_source(robot, motion, forced)
        return forced
    for source in SOURCES:
        if _exists(_source_file(robot, motion, source)):
            return source
    bvh = _source_file(robot, motion, "bvh")
    csv = _source_file(robot, motion, "csv")
    where = f"{bvh}" + (f" nor {csv}" if csv else " (and no dataset CSV folder is set)")
    raise PipelineError(
        f"no data for motion '{motion}': neither {where} exists; `rd-pipeline fetch-lafan` downloads "
        "LAFAN1's BVH files, or point RD_LAFAN_DIR (BVH files), RD_RETARGETED_DIR (dataset CSVs) and "
        f"RD_ROBOT_ASSETS (robot models) at the data, as variables or in {paths.SETTINGS_FILE}"
    )


def _source_file(robot: str | None, motion: str, source: str) -> Path | None:
    """The file a source reads; None for a dataset CSV without a robot or a CSV folder."""
    if source == "bvh":
        return paths.bvh_path(motion)
    return paths.csv_path(robot, motion) if robot else None


def _exists(path: Path | None) -> bool:
    return path is not None and path.is_file()


def _require_forced_source(robot: str | None, motion: str, forced: str) -> None:
    """A forced source whose file is missing is named in one line, with the sources the motion has."""
    wanted = _source_file(robot, motion, forced)
    if _exists(wanted):
        return
    present = paths.available_motions().get(motion, [])
    has = f"'{motion}' has: {', '.join(present)}" if present else f"'{motion}' has no source here"
    missing = f"{wanted} not found" if wanted is not None else "no dataset CSV folder or robot is set"
    raise PipelineError(f"--source {forced}: {missing}; {has}")
