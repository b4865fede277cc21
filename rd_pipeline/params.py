"""Layering stage parameters: profile < params file (`params.yaml`) < `--set stage.param=value`."""

from __future__ import annotations

import difflib
import math
from pathlib import Path
from typing import Any

import yaml

from rd_pipeline.errors import PipelineError, nearest
from rd_pipeline.profiles import load_profile

DEFAULT_PROFILE = "smoke"


class ParamRangeError(ValueError):
    """A param value outside its range, raised by a params dataclass; the reader adds the stage prefix."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field} {message}")
        self.field = field
        self.message = message


def require_positive(params: object, *fields: str) -> None:
    """Raise `ParamRangeError` for the first of `fields` of `params` that is not > 0."""
    for field in fields:
        value = getattr(params, field)
        if not value > 0:
            raise ParamRangeError(field, f"must be positive, got {value}")


def require_non_negative(params: object, *fields: str) -> None:
    """Raise `ParamRangeError` for the first of `fields` of `params` that is below 0."""
    for field in fields:
        value = getattr(params, field)
        if not value >= 0:
            raise ParamRangeError(field, f"must be at least 0, got {value}")


def require_at_most(params: object, limit: float, *fields: str) -> None:
    """Raise `ParamRangeError` for the first of `fields` of `params` above `limit`."""
    for field in fields:
        value = getattr(params, field)
        if value > limit:
            raise ParamRangeError(field, f"must be at most {limit:g}, got {value}")


def require_default_sign(name: str, value: Any, default: Any) -> None:
    """Every number is finite and keeps its default's sign: at least 0 where the default is (rates,
    gains, sigmas, thresholds, seeds), at most 0 where it is negative (penalty weights). Ranges
    tighter than that are the params dataclasses' own checks."""
    values = value if isinstance(value, tuple) else (value,)
    defaults = default if isinstance(default, tuple) else (default,)
    numbers = [v for v in values if isinstance(v, int | float) and not isinstance(v, bool)]
    if not numbers or len(numbers) != len(values) or not defaults:
        return
    negative = min(defaults) < 0
    for number in numbers:
        if not math.isfinite(number):
            raise PipelineError(f"parameter '{name}' must be finite, got {number}")
        if negative and number > 0:
            raise PipelineError(f"parameter '{name}' must be at most 0 like its default, got {number}")
        if not negative and number < 0:
            raise PipelineError(f"parameter '{name}' must be at least 0, got {number}")


def read_params_file(path: Path, stage_names: list[str]) -> tuple[str | None, dict[str, dict[str, Any]]]:
    """(profile, per-stage values) from a DVC-style params file with a `stages:` table."""
    try:
        raw = yaml.safe_load(path.read_text()) or {}
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise PipelineError(f"{path}: cannot read params file ({str(exc).splitlines()[0]})") from None
    if not isinstance(raw, dict):
        raise PipelineError(f"{path}: a params file is a mapping with a 'stages:' table, not a {type(raw).__name__}")
    if "stages" not in raw:
        close = difflib.get_close_matches("stages", [str(key) for key in raw], n=1)
        spelled = f" ('{close[0]}' is spelled like it)" if close else ""
        raise PipelineError(
            f"{path}: a params file sets params under a 'stages:' table, and this one has none{spelled}"
        )
    stages = raw["stages"] or {}
    if not isinstance(stages, dict):
        raise PipelineError(f"{path}: 'stages' must be a mapping of stage name to params")
    for name, values in stages.items():
        if name not in stage_names:
            known = ", ".join(stage_names)
            raise PipelineError(
                f"{path}: stages.{name} is not a stage{nearest(str(name), stage_names)} (stages: {known})"
            )
        if not isinstance(values, dict):
            raise PipelineError(f"{path}: stages.{name} must be a mapping of params")
    return raw.get("profile"), stages


def parse_assignments(assignments: tuple[str, ...], stage_names: list[str]) -> dict[str, dict[str, Any]]:
    """`stage.param=value` strings -> per-stage values (types are checked against the params later)."""
    values: dict[str, dict[str, Any]] = {}
    for item in assignments:
        target, sep, value = item.partition("=")
        stage, dot, param = target.partition(".")
        if not sep or not dot or not param:
            raise PipelineError(f"--set {item}: expected stage.param=value")
        if stage not in stage_names:
            raise PipelineError(f"--set {item}: unknown stage '{stage}' (stages: {', '.join(stage_names)})")
        values.setdefault(stage, {})[param] = value
    return values


def layered_params(
    profile: str | None, stage_names: list[str], params_file: Path | None, assignments: tuple[str, ...]
) -> tuple[str, dict[str, dict[str, Any]]]:
    """The profile's name and the per-stage values of the profile, then the params file, then
    `--set`, merged field by field:
    a later layer replaces only the fields it names, however deep (`train.env.num_envs` keeps the
    profile's `train.env.backend`)."""
    file_profile, file_values = read_params_file(params_file, stage_names) if params_file else (None, {})
    name = profile or file_profile or DEFAULT_PROFILE
    layers = [
        load_profile(name),
        file_values,
        parse_assignments(assignments, stage_names),
    ]
    merged: dict[str, Any] = {}
    for layer in layers:
        merge_into(merged, nested(layer))
    return name, merged


def nested(values: dict[str, Any]) -> dict[str, Any]:
    """The same values with every dotted name (`env.num_envs`, as `--set` gives them) spelled as
    nested mappings (as profiles and params files give them)."""
    result: dict[str, Any] = {}
    for name, value in values.items():
        head, *rest = name.split(".")
        inner = nested(value) if isinstance(value, dict) else value
        for part in reversed(rest):
            inner = {part: inner}
        merge_into(result, {head: inner})
    return result


def merge_into(target: dict[str, Any], values: dict[str, Any]) -> None:
    """Merge nested `values` into `target` in place, mapping into mapping; anything else replaces."""
    for name, value in values.items():
        if isinstance(value, dict) and isinstance(target.get(name), dict):
            merge_into(target[name], value)
        else:
            target[name] = value
