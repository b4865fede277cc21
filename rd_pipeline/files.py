"""File helpers below the store: content hashes, and array files read with one clear error when damaged."""

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


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
