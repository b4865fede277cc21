"""The one exception type users see: its message is the single line the CLI prints."""


class PipelineError(Exception):
    """Bad input or a missing prerequisite. The message names the file, field or value at fault."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a stage that keeps its progress; the message says where and how to continue."""
