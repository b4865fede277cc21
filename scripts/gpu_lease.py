"""Carry a GPU lease's training home: its train artifact packed under the lease's file limits.

    python -m scripts.gpu_lease pack <train artifact folder> <archive.tar.xz>   # on the GPU machine
    python -m scripts.gpu_lease unpack <archive.tar.xz> [--store DIR]          # here, then export/validate

`pack` archives the train artifact with the shorter runs it continued (a lease's probe). It drops
every checkpoint's per-rank state (the environments, sampler and generators: ~30 MB with 8192
environments) and keeps what `export` reads, the actor's weights; the newest checkpoint keeps the
whole algorithm (critic and optimizer too). The manifest is rewritten with the slimmed
files' sizes and sha256, so the store takes the artifact as complete. A slimmed artifact cannot be
resumed exactly: `--resume` needs the environments' state.
"""

from __future__ import annotations

import argparse
import json
import sys
import tarfile
from pathlib import Path

import torch

from rd_pipeline.api.workspace import continued_runs
from rd_pipeline.artifacts.store import MANIFEST
from rd_pipeline.errors import PipelineError
from rd_pipeline.files import file_sha256
from rd_pipeline.paths import artifacts_dir
from rd_pipeline.training.log import checkpoints_by_iteration


def main() -> None:
    args = _parser().parse_args()
    try:
        if args.command == "pack":
            pack(args.artifact, args.archive)
        else:
            unpack(args.archive, args.store or artifacts_dir())
    except (PipelineError, OSError, tarfile.TarError) as exc:
        sys.exit(f"error: {exc}")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    pack_command = commands.add_parser("pack", help="slim a train artifact and archive it")
    pack_command.add_argument("artifact", type=Path, help="the train artifact's folder")
    pack_command.add_argument("archive", type=Path)
    unpack_command = commands.add_parser("unpack", help="put a packed train artifact into the store")
    unpack_command.add_argument("archive", type=Path)
    unpack_command.add_argument("--store", type=Path, default=None, help="default: the configured store")
    return parser


def pack(artifact: Path, archive: Path) -> None:
    """Slim `artifact` and the shorter runs it continued, in place, and archive them all as
    `<stage>/<robot>/<motion>/<key>/`."""
    chain = continued_runs(artifact)
    for run in chain:
        _slim_artifact(run, whole_newest=run == artifact)
    archive.parent.mkdir(parents=True, exist_ok=True)
    with tarfile.open(archive, "w:xz") as tar:
        for run in chain:
            tar.add(run, arcname=run.relative_to(run.parents[3]))
    print(f"packed {[run.name for run in chain]} into {archive} ({archive.stat().st_size} bytes)")


def _slim_artifact(artifact: Path, whole_newest: bool) -> None:
    manifest_path = artifact / MANIFEST
    manifest = json.loads(manifest_path.read_text())
    checkpoints = list(checkpoints_by_iteration(artifact).values())
    for path in checkpoints:
        _slim(path, whole_algorithm=whole_newest and path == checkpoints[-1])
        name = path.relative_to(artifact).as_posix()
        manifest["files"][name] = {"sha256": file_sha256(path), "size": path.stat().st_size}
    manifest_path.write_text(json.dumps(manifest, indent=2) + "\n")


def _slim(checkpoint: Path, whole_algorithm: bool) -> None:
    state = torch.load(checkpoint, weights_only=False, map_location="cpu")
    algorithm = state["algorithm"]
    kept = algorithm if whole_algorithm else {"actor_state_dict": algorithm["actor_state_dict"]}
    slim = {key: value for key, value in state.items() if key != "ranks"}
    slim["algorithm"] = kept
    torch.save(slim, checkpoint)


def unpack(archive: Path, store: Path) -> None:
    """Extract packed artifacts into `store`, refusing any that is already there."""
    with tarfile.open(archive, "r:xz") as tar:
        tops = sorted({Path(*Path(name).parts[:4]) for name in tar.getnames() if len(Path(name).parts) >= 4})
        for top in tops:
            if (store / top).exists():
                raise PipelineError(f"{store / top} already exists")
        tar.extractall(store, filter="data")
    print(f"unpacked {[str(top) for top in tops]} into {store}")


if __name__ == "__main__":
    main()
