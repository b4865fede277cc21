"""A training's hours, from its log, into a result file.

    python -m scripts.training_hours <train artifact folder> [--into studies/results/dance_window_restart.json]

The log of a train artifact carries every iteration of every run the training continued (grown,
resumed, restored from a saved checkpoint, or a GPU lease's probe left on its machine), so its
hours are counted from the log, never from the runs still in the store. Prints them; with
`--into`, replaces the `wall_h*` fields of a result file an earlier commit's bench wrote, and
records which commit counted them (`hours_commit`).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from bench.common import head_commit, training_hours
from rd_pipeline.errors import PipelineError


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("train", type=Path, help="a train artifact's folder")
    parser.add_argument("--into", type=Path, default=None, help="a result file whose wall_h* fields to replace")
    args = parser.parse_args()
    try:
        hours = training_hours(args.train)
        if args.into is not None:
            _replace(args.into, hours)
    except (PipelineError, OSError, ValueError) as exc:
        sys.exit(f"error: {exc}")
    except KeyError as exc:
        sys.exit(f"error: {args.train}: a manifest or log row lacks the field {exc}")
    print(json.dumps(hours, indent=2))


def _replace(result_path: Path, hours: dict[str, Any]) -> None:
    try:
        result = json.loads(result_path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{result_path}: not a JSON result file ({exc})") from None
    if not isinstance(result, dict):
        raise ValueError(f"{result_path}: not a JSON result file (a {type(result).__name__}, not an object)")
    replaced: dict[str, Any] = {}
    for name, value in result.items():
        # the new hours take the place of the first old one, so the file reads as before
        if name.startswith("wall_h"):
            replaced.update(hours)
        else:
            replaced[name] = value
    replaced.update(hours)
    replaced["hours_commit"] = head_commit()
    result_path.write_text(json.dumps(replaced, indent=2) + "\n")


if __name__ == "__main__":
    main()
