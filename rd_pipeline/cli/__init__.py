"""The `rd-pipeline` command: arguments, commands, entry point."""

from rd_pipeline.cli.app import entry_point, main

__all__ = ["entry_point", "main"]
