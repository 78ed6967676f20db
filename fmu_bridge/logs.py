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
    whoever reads stderr of a node started by hand.
    """
    out: IO[str] = open(log_file, "a", buffering=1) if log_file else (stream or sys.stderr)  # noqa: SIM115
    structlog.configure(
        processors=[
            structlog.contextvars.merge_contextvars,
            structlog.processors.add_log_level,
            structlog.processors.TimeStamper(fmt="iso", utc=True),
            structlog.processors.JSONRenderer(),
        ],
        wrapper_class=structlog.make_filtering_bound_logger(logging.getLevelName(level.upper())),
        logger_factory=structlog.PrintLoggerFactory(out),
        cache_logger_on_first_use=False,
    )
