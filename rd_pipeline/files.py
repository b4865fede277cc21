"""File helpers below the store: content hashes, array files read with one clear error when
damaged, and files written whole or not at all."""

from __future__ import annotations

import hashlib
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from rd_pipeline.errors import PipelineError


@contextmanager
def open_npz(path: Path) -> Iterator[np.lib.npyio.NpzFile]:
    """`np.load` of an `.npz` whose failures (a truncated archive, a missing array) name the file."""
    try:
        with np.load(path) as data:
            yield data
    except (zipfile.BadZipFile, EOFError, KeyError, ValueError, OSError) as exc:
        raise PipelineError(
            f"{path}: cannot be read ({type(exc).__name__}: {exc}); `rd-pipeline run` recomputes a damaged artifact"
        ) from None


@contextmanager
def written_whole(path: Path, suffix: str = "") -> Iterator[Path]:
    """A hidden file beside `path` to write, which takes `path`'s place when the block ends and is
    removed when it fails: no reader sees half a file, and a failed write leaves nothing behind.
    `suffix` ends its name where the writer insists on one (`np.savez` adds `.npz`)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.name}.partial{suffix}")
    try:
        yield partial
        partial.replace(path)
    except BaseException:
        partial.unlink(missing_ok=True)
        raise


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
