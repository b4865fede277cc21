"""Validate an exported policy again with this commit's validation, outside the DAG.

    python -m scripts.revalidate <export artifact folder> --out <folder>

For exports that an installed older copy made (the long dance-window runs): their validation
predates what this commit reports (e.g. what ended each rollout). The reference is the artifact the
export names (`reference_key`), found in the same store; the protocol is the `validate` stage's
default. Writes report.json, report.md and the plots into `--out`, and prints report.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from rd_pipeline.artifacts.store import MANIFEST
from rd_pipeline.errors import PipelineError
from rd_pipeline.evaluation.report import REPORT_MD, plot_report, write_json, write_markdown
from rd_pipeline.evaluation.validation import load_exported_spec, reference_clip, rollout_pictures, validate_policy
from rd_pipeline.evaluation.validation_config import ValidationConfig
from rd_pipeline.robots import load_robot

REFERENCE_STAGES = ("retarget", "import")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("export", type=Path, help="an export artifact's folder")
    parser.add_argument("--out", type=Path, required=True, help="folder for report.json, report.md and plots")
    parser.add_argument(
        "--rule",
        default="",
        help="what chose the export's checkpoint, for an export older than policy.json's `checkpoint` block",
    )
    args = parser.parse_args()
    try:
        revalidate(args.export.resolve(), args.out, args.rule)
    except (PipelineError, OSError) as exc:
        sys.exit(f"error: {args.export}: {exc}")
    print((args.out / REPORT_MD).read_text())


def revalidate(export: Path, out: Path, rule: str = "") -> None:
    """Validate the export artifact in `export` (an absolute path into a store) into `out`;
    `rule` names what chose its checkpoint where the export does not say."""
    manifest = _export_manifest(export)
    reference_key = manifest["metrics"]["reference_key"]
    store = export.parents[3]  # <store>/export/<robot>/<motion>/<key>
    stage, folder = _reference(store, manifest["robot"], manifest["motion"], reference_key)
    spec = load_exported_spec(export, reference_key)
    clip = reference_clip(spec, stage, reference_key, folder)
    robot = load_robot(manifest["robot"])
    config = ValidationConfig()
    validation = validate_policy(robot, manifest["motion"], export, manifest["key"], clip, config)
    out.mkdir(parents=True, exist_ok=True)
    report = validation.report.details
    if rule and not report["checkpoint"]:
        report["checkpoint"] = {"iteration": manifest["metrics"]["checkpoint_iteration"], "rule": rule}
    report["pictures"] = rollout_pictures(validation, clip, config.render, out)
    write_json(report, out)
    write_markdown(report, out)
    plot_report(report, out)


def _export_manifest(export: Path) -> dict[str, Any]:
    """The export's manifest, or one line saying why it is not one."""
    try:
        manifest = json.loads((export / MANIFEST).read_text())
    except json.JSONDecodeError as exc:
        raise PipelineError(f"{MANIFEST} is not JSON ({exc})") from None
    if not isinstance(manifest, dict) or manifest.get("stage") != "export" or len(export.parents) < 4:
        raise PipelineError("not an export artifact's folder (<store>/export/<robot>/<motion>/<key>)")
    for name in ("robot", "motion", "key"):
        if name not in manifest:
            raise PipelineError(f"{MANIFEST} lacks the field '{name}'")
    if "reference_key" not in manifest.get("metrics", {}):
        raise PipelineError(f"{MANIFEST} lacks the metric 'reference_key'")
    return manifest


def _reference(store: Path, robot: str, motion: str, key: str) -> tuple[str, Path]:
    for stage in REFERENCE_STAGES:
        folder = store / stage / robot / motion / key
        if (folder / MANIFEST).is_file():
            return stage, folder
    raise PipelineError(f"its reference {key} is in neither {' nor '.join(REFERENCE_STAGES)} of {store}")


if __name__ == "__main__":
    main()
