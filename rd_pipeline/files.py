"""File helpers below the store: content hashes, array files read with one clear error when
damaged, and files written whole or not at all."""

from __future__ import annotations

import errno
import hashlib
import shutil
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


def write_bytes_whole(path: Path, data: bytes) -> None:
    """Write `data` to `path` whole or not at all: a disk that refuses it leaves nothing behind
    and is one line naming the folder and the bytes it needed."""
    try:
        with written_whole(path) as partial:
            partial.write_bytes(data)
    except OSError as exc:
        if failed_write(exc) is None:
            raise
        raise write_failure(exc, path.parent, len(data), exact=True) from None


_WRITE_FAILURES = {
    errno.ENOSPC: "no space left on its disk",
    errno.EDQUOT: "the disk quota is used up",
    errno.EFBIG: "a file grew past this process's size limit (ulimit -f)",
    errno.EROFS: "its file system is read-only",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
}


def failed_write(exc: BaseException) -> OSError | None:
    """The OSError of a write that failed for want of space or permission, found in `exc` or
    the exceptions it was raised from or during (writers wrap it in their own); else None."""
    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, OSError) and seen.errno in _WRITE_FAILURES:
            return seen
        seen = seen.__cause__ or seen.__context__
    return None


def write_failure(cause: OSError, folder: Path, needed: int, exact: bool = False) -> PipelineError:
    """One line for a write into `folder` that failed: why, the bytes it `needed` (with `exact`
    False: had written before failing, so it needed more), what is free."""
    reason = _WRITE_FAILURES.get(cause.errno or 0, cause.strerror or str(cause))
    line = f"cannot write {folder}: {reason}"
    if cause.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        free = _free_bytes(folder)
        line += f"; it needed {'' if exact else 'more than '}{_size(needed)}"
        line += f" ({_size(free)} free there)" if free is not None else ""
        line += "; free some space and run again"
    return PipelineError(line)


def folder_bytes(*folders: Path) -> int:
    """Bytes of the files under `folders` (those that exist)."""
    files = (p for folder in folders if folder.is_dir() for p in folder.rglob("*"))
    return sum(p.stat().st_size for p in files if p.is_file())


def _free_bytes(folder: Path) -> int | None:
    for place in (folder, *folder.parents):
        if place.exists():
            return shutil.disk_usage(place).free
    return None


def _size(count: int) -> str:
    return f"{count / 2**20:.1f} MiB"


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
