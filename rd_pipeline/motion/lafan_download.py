"""Installing the official LAFAN1 archive (Ubisoft La Forge, CC BY-NC-ND 4.0) after checking its checksum."""

from __future__ import annotations

import os
import tempfile
import urllib.request
import zipfile
from pathlib import Path

from rich.console import Console
from rich.progress import DownloadColumn, Progress, TransferSpeedColumn

from rd_pipeline.errors import PipelineError
from rd_pipeline.files import file_sha256

LAFAN_URL = (
    "https://media.githubusercontent.com/media/ubisoft/ubisoft-laforge-animation-dataset/master/lafan1/lafan1.zip"
)
LAFAN_SHA256 = "ea918082b500a5d158e9d3aa39039df04cd42e25f5c02fe8f7e88e8e9365a977"
LAFAN_BYTES = 144_051_503


def install_lafan(zip_path: Path | None, target: Path, console: Console) -> list[Path]:
    """Check (downloading first if no `zip_path`) and unpack every BVH of lafan1.zip into `target`."""
    if zip_path is None:
        zip_path = _download(console)
    if not zip_path.is_file():
        raise PipelineError(f"{zip_path}: file not found")
    digest = file_sha256(zip_path)
    if digest != LAFAN_SHA256:
        raise PipelineError(f"{zip_path}: sha256 {digest} is not the official lafan1.zip ({LAFAN_SHA256})")
    target.mkdir(parents=True, exist_ok=True)
    installed = []
    with zipfile.ZipFile(zip_path) as archive:
        for member in archive.namelist():
            if not member.lower().endswith(".bvh"):
                continue
            destination = target / Path(member).name
            # Unpack beside the destination, then rename: a killed install leaves no truncated BVH.
            with tempfile.NamedTemporaryFile(dir=target, delete=False, suffix=".partial") as handle:
                handle.write(archive.read(member))
            os.replace(handle.name, destination)
            installed.append(destination)
    return installed


def _download(console: Console) -> Path:
    # A mirror may stand in for the official address; the sha256 check stays the same.
    url = os.environ.get("RD_LAFAN_URL", LAFAN_URL)
    destination = Path(tempfile.gettempdir()) / "lafan1.zip"
    try:
        with urllib.request.urlopen(url, timeout=30) as response, destination.open("wb") as handle:
            with Progress(
                *Progress.get_default_columns(), DownloadColumn(), TransferSpeedColumn(), console=console
            ) as bar:
                task = bar.add_task("lafan1.zip", total=LAFAN_BYTES)
                for block in iter(lambda: response.read(1 << 20), b""):
                    handle.write(block)
                    bar.advance(task, len(block))
    except OSError as exc:
        raise PipelineError(f"download of {url} failed ({exc}); download it by hand and pass --zip") from None
    return destination
