"""The ``hycosim`` command line: one module per domain of commands under ``commands``, the
output, option checks and project loading they share beside them. User-facing output goes
through here, not through logs."""

from hycosim.cli.main import app, main

__all__ = ["app", "main"]
