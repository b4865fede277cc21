"""Planning a run: the stages of one (robot, motion) in dependency order, the ones a run
selects, and the key of each (nothing is read from or written to the store here)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

from rd_pipeline import paths
from rd_pipeline.artifacts.keys import artifact_key
from rd_pipeline.artifacts.stage import Stage, build_params
from rd_pipeline.errors import PipelineError
from rd_pipeline.files import file_sha256


@dataclass(frozen=True)
class PlannedStage:
    """A stage with everything that determines its artifact key."""

    stage: Stage
    """The stage."""
    params: Any
    """Its resolved params."""
    inputs: dict[str, Path]
    """External input files by label."""
    input_hashes: dict[str, str]
    """sha256 of each input file."""
    upstream: dict[str, str]
    """Upstream stage name -> key."""
    key: str
    """The artifact key."""

    @property
    def name(self) -> str:
        return self.stage.name


@dataclass(frozen=True)
class Pipeline:
    """The stages of one run: a registry, a robot, a motion, a source, params."""

    registry: tuple[Stage, ...]
    """All stages that exist."""
    robot: str | None
    """Robot name; stages that are per robot need one."""
    motion: str
    """Motion name."""
    source: str
    """`bvh` or `csv`."""
    param_values: dict[str, dict[str, Any]]
    """Stage name -> param overrides (profile, params file and `--set`, already layered)."""

    @cached_property
    def params(self) -> dict[str, Any]:
        """Stage name -> its typed params, built once from `param_values` (every value checked)."""
        return {stage.name: build_params(stage, self.param_values.get(stage.name, {})) for stage in self.registry}

    def stage_robot(self, stage: Stage) -> str | None:
        """The robot a stage's artifact belongs to (None for the stages shared by every robot)."""
        return self.robot if stage.per_robot else None

    def label(self, stage: Stage) -> str:
        """`robot/motion`, or the motion alone for a stage shared by every robot."""
        robot = self.stage_robot(stage)
        return f"{robot}/{self.motion}" if robot else self.motion

    def chain(self) -> list[Stage]:
        """Stages of this source in dependency order (registry order breaks ties)."""
        candidates = [s for s in self.registry if s.source in (None, self.source)]
        ordered: list[Stage] = []
        provided: set[str] = set()
        progress = True
        while progress:
            progress = False
            for stage in candidates:
                if stage not in ordered and all(role in provided for role in stage.requires):
                    ordered.append(stage)
                    provided.add(stage.provides)
                    progress = True
        return ordered

    def select(self, start: str | None, until: str | None, only: str | None) -> tuple[list[Stage], list[Stage]]:
        """(stages to run, upstream stages that must already be cached)."""
        chain = self.chain()
        names = [s.name for s in chain]
        for option, value in (("--from", start), ("--until", until), ("--only", only)):
            if value is None:
                continue
            if value not in {s.name for s in self.registry}:
                known = ", ".join(s.name for s in self.registry)
                raise PipelineError(f"{option}: unknown stage '{value}' (stages: {known})")
            if value not in names:
                raise PipelineError(
                    f"{option}: stage '{value}' is not in the {self.source} pipeline for "
                    f"{self.robot}/{self.motion} (stages: {', '.join(names)})"
                )
        if only is not None:
            if start is not None or until is not None:
                given = "--from" if start is not None else "--until"
                raise PipelineError(f"--only runs one stage; it cannot be combined with {given}")
            start = until = only
        first = names.index(start) if start else 0
        last = names.index(until) if until else len(chain) - 1
        if first > last:
            raise PipelineError(f"--from {start} comes after --until {until}")
        return chain[first : last + 1], chain[:first]

    def plan(self, stages: list[Stage]) -> list[PlannedStage]:
        """Keys for `stages` (which must include their upstream, in order)."""
        planned: list[PlannedStage] = []
        by_role: dict[str, PlannedStage] = {}
        for stage in stages:
            if stage.per_robot and not self.robot:
                raise PipelineError(f"stage '{stage.name}' needs --robot")
            params = self.params[stage.name]
            inputs = stage.inputs(self.robot if stage.per_robot else None, self.motion)
            for label, path in inputs.items():
                paths.require_file(path, f"input '{label}' of stage {stage.name}")
            hashes = {label: file_sha256(path) for label, path in sorted(inputs.items())}
            upstream = {by_role[role].stage.name: by_role[role].key for role in stage.requires}
            key = artifact_key(stage.name, stage.version, dataclasses.asdict(params), upstream, hashes)
            entry = PlannedStage(stage, params, inputs, hashes, upstream, key)
            planned.append(entry)
            by_role[stage.provides] = entry
        return planned
