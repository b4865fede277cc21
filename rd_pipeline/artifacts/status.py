"""What a run would find in the store, stage by stage: cached, damaged, running, resumable,
stale or missing."""

from __future__ import annotations

from typing import Any

from rd_pipeline.artifacts.plan import Pipeline
from rd_pipeline.artifacts.store import ArtifactStore
from rd_pipeline.errors import PipelineError


def stage_status(pipeline: Pipeline, store: ArtifactStore, verify: bool = False) -> list[dict[str, Any]]:
    """Per stage of the chain: key, path and state (cached / damaged / resumable / stale / missing),
    or the reason there is no key. File sizes are always checked, their sha256 with `verify`."""
    rows = []
    chain = pipeline.chain()
    for i, stage in enumerate(chain):
        robot = pipeline.stage_robot(stage)
        row: dict[str, Any] = {"stage": stage.name, "robot": robot, "motion": pipeline.motion}
        try:
            entry = pipeline.plan(chain[: i + 1])[-1]
        except PipelineError as exc:
            rows.append({**row, "key": None, "path": None, "state": "missing", "reason": str(exc)})
            continue
        found = store.find(stage.name, robot, pipeline.motion, entry.key)
        damage = found.damage(verify) if found else None
        others = [k for k in store.keys(stage.name, robot, pipeline.motion) if k != entry.key]
        work = store.work_folder(stage.name, robot, pipeline.motion, entry.key)
        running = not found and store.running(stage.name, robot, pipeline.motion, entry.key)
        kept = not found and not running and work.is_dir() and any(work.iterdir())
        continues, progress = stage.kept_progress(work) if kept else (False, "")
        damage = damage or (progress if kept and not continues else None)
        states = (("damaged", damage), ("cached", found), ("running", running), ("resumable", kept), ("stale", others))
        state = next((name for name, holds in states if holds), "missing")
        path = store.folder(stage.name, robot, pipeline.motion) / entry.key
        rows.append({**row, "key": entry.key, "path": str(path), "state": state, "other_keys": others})
        if damage:
            rows[-1]["reason"] = damage
        elif kept:
            rows[-1]["reason"] = progress
        elif running:
            rows[-1]["reason"] = "another run is computing it now"
    return rows
