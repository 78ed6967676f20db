"""structlog setup: JSON lines to a file, with node and step bound as context by callers."""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import IO

import structlog


def configure(log_file: Path | None = None, level: str = "info", stream: IO[str] | None = None) -> None:
    """Send structlog events as JSON lines to ``log_file`` (appended) or to ``stream``.

    User-facing output goes through the CLI; logs are for the run directory and for
    whoever reads stderr of a node started by hand: JSON lines for a collector (docker logs,
    a file), aligned text with colours when that stderr is a terminal.
    """
    out: IO[str] = open(log_file, "a", buffering=1) if log_file else (stream or sys.stderr)  # noqa: SIM115
    terminal = log_file is None and out.isatty()
    structlog.configure(
        processors=[
            structlog.contextvars.merge_contextvars,
            structlog.processors.add_log_level,
            structlog.processors.TimeStamper(fmt="%H:%M:%S" if terminal else "iso", utc=not terminal),
            structlog.dev.ConsoleRenderer() if terminal else structlog.processors.JSONRenderer(),
        ],
        wrapper_class=structlog.make_filtering_bound_logger(logging.getLevelName(level.upper())),
        logger_factory=structlog.PrintLoggerFactory(out),
        cache_logger_on_first_use=False,
    )
