"""`policy.json`: everything a deploy loop needs beside the TorchScript file.

Gains, default pose, action scale and clip, the residual mask, the observation layout and the rates
travel with the weights, so a robot-side loop never reads training code or configs. Loading checks
every field and names the first one that is missing or has the wrong type.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rd_pipeline.errors import PipelineError

FORMAT_VERSION = 2
POLICY_FILE = "policy.pt"
SPEC_FILE = "policy.json"
ONNX_FILE = "policy.onnx"
"""File name of the ONNX policy inside an export artifact."""

_NUMBER = (int, float)
# Dotted field -> expected type; lists are checked element-wise and per-joint lists for their length.
SCHEMA: dict[str, Any] = {
    "format_version": int,
    "robot": str,
    "mjcf": str,
    "joints.actuated": [str],
    "joints.policy": [str],
    "joints.kp": [_NUMBER],
    "joints.kd": [_NUMBER],
    "joints.effort_limit": [_NUMBER],
    "joints.default_pos": [_NUMBER],
    "joints.policy_lower": [_NUMBER],
    "joints.policy_upper": [_NUMBER],
    "action.mode": str,
    "action.scale": _NUMBER,
    "action.clip": _NUMBER,
    "action.residual_mask": [int],
    "action.outputs": [str],
    "action.semantics": [str],
    "observation.history": int,
    "observation.frame_size": int,
    "observation.size": int,
    "observation.order": str,
    "observation.terms": [dict],
    "rates.control_hz": _NUMBER,
    "rates.physics_hz": _NUMBER,
    "reference.stage": str,
    "reference.key": str,
    "reference.start_frame": int,
    "reference.end_frame": int,
}
_PER_ACTUATED = ("joints.kp", "joints.kd", "joints.effort_limit", "joints.default_pos")
_PER_POLICY = ("joints.policy_lower", "joints.policy_upper")
SEMANTICS = ("residual", "absolute", "reference")
"""Per policy joint, how its target is formed (see `rd_pipeline.env.mdp.actions`)."""


@dataclass(frozen=True)
class PolicySpec:
    """A checked `policy.json` (the raw nested dict, with typed accessors for what loops use)."""

    data: dict
    """The document."""

    def get(self, dotted: str) -> Any:
        value: Any = self.data
        for part in dotted.split("."):
            value = value[part]
        return value

    def save(self, path: Path) -> None:
        path.write_text(json.dumps(self.data, indent=2) + "\n")


def _check(data: Any, source: Path) -> None:
    _check_schema(data, source)
    if data["format_version"] != FORMAT_VERSION:
        raise PipelineError(f"{source}: format_version {data['format_version']} is not {FORMAT_VERSION}")
    _check_joints(data["joints"], source)
    _check_action(data["action"], data["joints"]["policy"], source)
    _check_observation(data["observation"], len(data["joints"]["policy"]), source)


def _check_schema(data: Any, source: Path) -> None:
    """Every field of `SCHEMA` is there, of its type."""
    for dotted, kind in SCHEMA.items():
        value: Any = data
        for depth, part in enumerate(dotted.split(".")):
            if not isinstance(value, dict) or part not in value:
                where = ".".join(dotted.split(".")[: depth + 1])
                raise PipelineError(f"{source}: field '{where}' is missing")
            value = value[part]
        element = kind[0] if isinstance(kind, list) else None
        if element is not None:
            if not isinstance(value, list) or not all(
                isinstance(v, element) and not isinstance(v, bool) for v in value
            ):
                raise PipelineError(f"{source}: field '{dotted}' must be a list of {_name(element)}")
        elif not isinstance(value, kind) or isinstance(value, bool):
            raise PipelineError(f"{source}: field '{dotted}' must be {_name(kind)}, got {value!r}")


def _check_joints(joints: dict[str, Any], source: Path) -> None:
    """One value per actuated joint, or per policy joint, in each per-joint list."""
    for dotted in _PER_ACTUATED + _PER_POLICY:
        expected = len(joints["actuated"] if dotted in _PER_ACTUATED else joints["policy"])
        if len(joints[dotted.split(".")[1]]) != expected:
            raise PipelineError(
                f"{source}: field '{dotted}' has {len(joints[dotted.split('.')[1]])} values, expected {expected}"
            )


def _check_action(action: dict[str, Any], policy: list[str], source: Path) -> None:
    """A known semantics per policy joint, and outputs for exactly the joints the policy drives."""
    if len(action["semantics"]) != len(policy):
        raise PipelineError(
            f"{source}: field 'action.semantics' has {len(action['semantics'])} values, expected {len(policy)}"
        )
    for kind in action["semantics"]:
        if kind not in SEMANTICS:
            raise PipelineError(f"{source}: field 'action.semantics' has '{kind}' (allowed: {', '.join(SEMANTICS)})")
    driven = [joint for joint, kind in zip(policy, action["semantics"]) if kind != "reference"]
    if action["outputs"] != driven:
        raise PipelineError(
            f"{source}: field 'action.outputs' must list the policy joints whose semantics "
            "is not 'reference', in policy order"
        )


def _check_observation(observation: dict[str, Any], policy_joints: int, source: Path) -> None:
    """Terms with a name, size and scale, summing to the frame and, with the history, the whole;
    the future reference frames' term as large as its steps say."""
    terms = observation["terms"]
    for i, term in enumerate(terms):
        for name, kind in (("name", str), ("size", int), ("scale", _NUMBER)):
            if not isinstance(term.get(name), kind):
                raise PipelineError(f"{source}: field 'observation.terms[{i}].{name}' is missing or not {_name(kind)}")
    frame = sum(t["size"] for t in terms)
    if frame != observation["frame_size"] or frame * observation["history"] != observation["size"]:
        raise PipelineError(f"{source}: field 'observation.size' does not match its terms and history")
    # Optional: only an actor that sees reference frames further ahead than the next has them.
    steps = observation.get("ref_future_steps", [])
    if not isinstance(steps, list) or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 1 for s in steps):
        raise PipelineError(f"{source}: field 'observation.ref_future_steps' must be a list of integers of 1 or more")
    future = sum(t["size"] for t in terms if t["name"] == "ref_joint_pos_future")
    if future != len(steps) * policy_joints:
        raise PipelineError(
            f"{source}: field 'observation.ref_future_steps' names {len(steps)} steps of {policy_joints} joints, "
            f"but the term 'ref_joint_pos_future' holds {future} values"
        )


def _name(kind: Any) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    return " or ".join({int: "an integer", float: "a number", str: "a string", dict: "an object"}[k] for k in kinds)


def load_policy_spec(path: Path) -> PolicySpec:
    """Read and check a `policy.json`; any problem is one `PipelineError` line naming the field."""
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise PipelineError(f"{path}: no such file") from None
    except json.JSONDecodeError as exc:
        raise PipelineError(f"{path}:{exc.lineno}: not valid JSON ({exc.msg})") from None
    _check(data, path)
    return PolicySpec(data)
