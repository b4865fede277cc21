"""Content-addressed artifact keys (SPEC: sha256 over stage, version, params, upstream keys, inputs)."""

from __future__ import annotations

import hashlib
import json
from typing import Any

KEY_LENGTH = 12


def canonical_json(value: Any) -> str:
    """JSON with sorted keys and no whitespace: the same value always gives the same bytes."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)


def artifact_key(
    stage: str, version: int, params: dict[str, Any], upstream: dict[str, str], input_hashes: dict[str, str]
) -> str:
    """First 12 hex chars of sha256 over the canonical description of a stage run.

    Inputs enter by label and content hash, not by path, so the key does not depend on where the
    data lives on a machine.
    """
    payload = {"stage": stage, "version": version, "params": params, "upstream": upstream, "inputs": input_hashes}
    return hashlib.sha256(canonical_json(payload).encode()).hexdigest()[:KEY_LENGTH]
