"""structlog setup: JSON lines to a file, with node and step bound as context by callers."""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import IO

import structlog


class _LossyStream:
    """A log stream whose write errors (a full disk) are swallowed: losing log lines is better
    than a node or the server failing on one. The first loss is said once on stderr."""

    def __init__(self, stream: IO[str]):
        self._stream = stream
        self.lost = 0

    def _lose(self, exc: OSError) -> None:
        if not self.lost and self._stream is not sys.stderr:
            try:
                print(f"hycosim: log lines are being lost: {getattr(self._stream, 'name', 'log')}: "
                      f"{exc.strerror or exc}", file=sys.stderr, flush=True)
            except OSError:
                pass
        self.lost += 1

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except OSError as exc:
            self._lose(exc)
            return 0

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError as exc:
            self._lose(exc)


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
            # log.exception(...) in a JSON line: the traceback as text under "exception" (without
            # this processor the line said only "exc_info": true).
            *([] if terminal else [structlog.processors.format_exc_info]),
            structlog.dev.ConsoleRenderer() if terminal else structlog.processors.JSONRenderer(),
        ],
        wrapper_class=structlog.make_filtering_bound_logger(logging.getLevelName(level.upper())),
        # One write a line (the line and its newline together): processes sharing one stdout
        # (containers, nodes started by hand with PYTHONUNBUFFERED) would otherwise
        # interleave a line of one with the newline of another.
        logger_factory=structlog.WriteLoggerFactory(_LossyStream(out)),
        cache_logger_on_first_use=False,
    )
