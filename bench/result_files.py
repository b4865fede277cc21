"""How a bench script leaves its result: the figures as JSON and a table to read, side by side."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def write_result(out: Path, result: Any, table: str) -> None:
    """Write `<out>.json` (the result) and `<out>.md` (its table), and print the table."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(result, indent=2) + "\n")
    out.with_suffix(".md").write_text(table)
    print(table)
