"""The artifact store: `<root>/<stage>/[<robot>/]<motion>/<key>/` folders with a `manifest.json`.

An artifact is written into a hidden temporary sibling folder and renamed into place only after
its manifest is written, so a crash, Ctrl-C or full disk never leaves a folder that looks complete.
The manifest lists every file's size and sha256, so a file damaged later is noticed, and one lock
file per key lets concurrent runs of the same key take turns instead of colliding.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rd_pipeline.artifacts.sources import check_motion_name
from rd_pipeline.errors import PipelineError
from rd_pipeline.files import file_sha256

MANIFEST = "manifest.json"
TEMP_PREFIX = ".tmp-"
LOCK_PREFIX = ".lock-"
WORK_PREFIX = ".work-"


@dataclass(frozen=True)
class ArtifactRef:
    """A complete artifact on disk."""

    stage: str
    """Stage that wrote it."""
    key: str
    """Its content key."""
    path: Path
    """Its folder."""

    @property
    def manifest(self) -> dict[str, Any]:
        return json.loads((self.path / MANIFEST).read_text())

    def damage(self, full: bool = False) -> str | None:
        """What is wrong with the artifact's files, or None: the manifest must parse and every file
        it lists must exist with its recorded size, and with `full` its recorded sha256.

        Artifacts written before manifests listed their files pass on the manifest alone.
        """
        try:
            files = self.manifest.get("files", {})
        except (OSError, ValueError) as exc:
            return f"{MANIFEST} cannot be read ({exc})"
        for name, record in files.items():
            path = self.path / name
            if not path.is_file():
                return f"{name} is missing"
            size = path.stat().st_size
            if size != record["size"]:
                return f"{name} is {size} bytes, the manifest says {record['size']}"
            if full and file_sha256(path) != record["sha256"]:
                return f"{name} does not match its sha256 in the manifest"
        return None


@dataclass(frozen=True)
class Claim:
    """A key's lock held: either the artifact a concurrent run finished while this one waited,
    or the folders this run writes it into."""

    made: ArtifactRef | None
    """The artifact another run made meanwhile (nothing to do), or None."""
    out: Path | None
    """The temporary folder that becomes the artifact (None where `made`)."""
    work: Path
    """Where a long stage keeps its progress for the key until it finishes."""


class ArtifactStore:
    """Artifact folders under one root."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def folder(self, stage: str, robot: str | None, motion: str) -> Path:
        """The folder holding every key of one stage for one (robot, motion)."""
        check_motion_name(motion)
        parts = [stage] + ([robot] if robot else []) + [motion]
        return self.root.joinpath(*parts)

    def work_folder(self, stage: str, robot: str | None, motion: str, key: str) -> Path:
        """Where a long stage keeps its progress for `key` (checkpoints) until it finishes."""
        return self.folder(stage, robot, motion) / f"{WORK_PREFIX}{key}"

    def find(self, stage: str, robot: str | None, motion: str, key: str) -> ArtifactRef | None:
        path = self.folder(stage, robot, motion) / key
        return ArtifactRef(stage, key, path) if (path / MANIFEST).is_file() else None

    def keys(self, stage: str, robot: str | None, motion: str) -> list[str]:
        """Keys of the complete artifacts present, newest first."""
        folder = self.folder(stage, robot, motion)
        if not folder.is_dir():
            return []
        done = [p for p in folder.iterdir() if not p.name.startswith(".") and (p / MANIFEST).is_file()]
        return [p.name for p in sorted(done, key=lambda p: (p / MANIFEST).stat().st_mtime, reverse=True)]

    @contextmanager
    def writing(self, stage: str, robot: str | None, motion: str, key: str, replace: bool = False) -> Iterator[Path]:
        """Yield a temporary folder; on normal exit it becomes the artifact, on any error it is removed.

        The caller writes `manifest.json` last; an artifact without one is never renamed into place.
        With `replace` (a forced rerun) an existing artifact of the same key is swapped out only once
        the new one is complete.
        """
        folder = self.folder(stage, robot, motion)
        self._make_folder(folder)
        temp = folder / f"{TEMP_PREFIX}{key}-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        self._make_folder(temp)
        try:
            yield temp
            if not (temp / MANIFEST).is_file():
                raise RuntimeError(f"stage {stage} finished without writing {MANIFEST}")
            final = folder / key
            # A folder without a manifest under the key is no artifact (emptied by hand, or a copy
            # cut short): the new one takes its place.
            stale = final.exists() and not (final / MANIFEST).is_file()
            if final.exists() and (replace or stale):
                old = folder / f"{TEMP_PREFIX}old-{key}-{os.getpid()}-{uuid.uuid4().hex[:8]}"
                os.replace(final, old)
                os.replace(temp, final)
                shutil.rmtree(old, ignore_errors=True)
            elif final.exists():  # another process finished the same key first; its result is identical
                shutil.rmtree(temp)
            else:
                os.replace(temp, final)
        except BaseException:
            shutil.rmtree(temp, ignore_errors=True)
            raise

    @contextmanager
    def claim(
        self,
        stage: str,
        robot: str | None,
        motion: str,
        key: str,
        redo: bool = False,
        on_wait: Callable[[], None] = lambda: None,
    ) -> Iterator[Claim]:
        """Take the key's lock (waiting for a concurrent run of it) and yield what to do: the
        whole artifact that run made, or, after clearing what a killed run left, a folder to write
        into (see `writing`). With `redo` an existing artifact is made again and replaced."""
        with self.locked(stage, robot, motion, key, on_wait):
            found = self.find(stage, robot, motion, key)
            work = self.work_folder(stage, robot, motion, key)
            if found is not None and not redo and found.damage(full=True) is None:
                yield Claim(found, None, work)
                return
            self.remove_abandoned(stage, robot, motion, key)
            with self.writing(stage, robot, motion, key, replace=found is not None) as out:
                yield Claim(None, out, work)

    @contextmanager
    def locked(
        self, stage: str, robot: str | None, motion: str, key: str, on_wait: Callable[[], None] = lambda: None
    ) -> Iterator[None]:
        """Hold the key's lock: a second run of the same key waits here (calling `on_wait` once)
        until the first has finished, then finds its artifact. The lock dies with its process."""
        folder = self.folder(stage, robot, motion)
        self._make_folder(folder)
        path = folder / f"{LOCK_PREFIX}{key}"
        waited = False
        while True:
            try:
                handle = path.open("a")
            except OSError as exc:
                raise self._unwritable(exc) from None
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                if not waited:
                    on_wait()
                    waited = True
                fcntl.flock(handle, fcntl.LOCK_EX)
            # The holder before us removes the file on release; a lock on a removed file guards nothing.
            if _same_file(path, handle):
                break
            handle.close()
        try:
            yield
        finally:
            path.unlink(missing_ok=True)
            handle.close()

    def running(self, stage: str, robot: str | None, motion: str, key: str) -> bool:
        """Whether a run holds the key's lock now (a killed run's lock file is held by no one)."""
        path = self.folder(stage, robot, motion) / f"{LOCK_PREFIX}{key}"
        try:
            handle = path.open("rb")
        except OSError:
            return False
        with handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                return True
            fcntl.flock(handle, fcntl.LOCK_UN)
        return False

    def _make_folder(self, folder: Path) -> None:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise self._unwritable(exc) from None

    def _unwritable(self, exc: OSError) -> PipelineError:
        """One line for a store that cannot be written (a read-only mount, no permission, a full disk)."""
        return PipelineError(
            f"cannot write the artifact store {self.root} ({exc.strerror}); set RD_ARTIFACTS to a writable folder"
        )

    def remove_abandoned(self, stage: str, robot: str | None, motion: str, key: str) -> int:
        """Delete the temporary folders a killed run of `key` left. Call it holding the key's lock:
        whatever made them has stopped. Other keys' are left alone, as a process on another machine
        sharing the store may be writing them."""
        folder = self.folder(stage, robot, motion)
        removed = 0
        for pattern in (f"{TEMP_PREFIX}{key}-*", f"{TEMP_PREFIX}old-{key}-*"):
            for temp in folder.glob(pattern) if folder.is_dir() else []:
                shutil.rmtree(temp, ignore_errors=True)
                removed += 1
        return removed


def _same_file(path: Path, handle: Any) -> bool:
    try:
        return os.stat(path).st_ino == os.fstat(handle.fileno()).st_ino
    except FileNotFoundError:
        return False
