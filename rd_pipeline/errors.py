"""The one exception type users see: its message is the single line the CLI prints."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class PipelineError(Exception):
    """Bad input or a missing prerequisite. The message names the file, field or value at fault."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a stage that keeps its progress; the message says where and how to continue."""


class ShareDone(Exception):
    """This machine's share of a multi-machine stage finished and another machine writes the
    artifact: not a failure. The CLI prints the message and exits 0."""


def nearest(name: str, known: Iterable[str]) -> str:
    """` (did you mean 'x'?)` naming the known name spelled most like `name`, or nothing."""
    close = difflib.get_close_matches(name, list(known), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""
