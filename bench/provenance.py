"""Which code a bench result came from, for the result files."""

from __future__ import annotations

import subprocess
from pathlib import Path


def head_commit() -> str:
    """The checkout's commit, when the bench runs from one (an installed copy has none: "unknown")."""
    git = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=Path(__file__).parent
    )
    return git.stdout.strip() or "unknown"
