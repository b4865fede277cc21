"""The one exception type users see: its message is the single line the CLI prints."""


class PipelineError(Exception):
    """Bad input or a missing prerequisite. The message names the file, field or value at fault."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a stage that keeps its progress; the message says where and how to continue."""


class ShareDone(Exception):
    """This machine's share of a multi-machine stage finished and another machine writes the
    artifact: not a failure. The CLI prints the message and exits 0."""
