"""Reading the line files of a run directory (``values.csv``, ``timing.csv``, ``events.jsonl``).

The server appends one line per macro step or event and flushes often, so a run that was
killed (SIGKILL, power loss) leaves every line it finished on disk, and perhaps half of
the next one. Readers here keep the finished lines and leave out a last line that has no
newline: a torn write, not data. A malformed line anywhere else is an error naming the
file and the line, since nothing the server writes looks like that.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

from hycosim.core import json_text


class RunFileError(RuntimeError):
    """A run file that cannot be read; the message names the file (and line)."""


class MissingColumns(RunFileError):
    """A CSV file whose header lacks columns the reader requires (``columns``)."""

    def __init__(self, path: Path, columns: list[str]):
        super().__init__(f"{path}: no column {', '.join(columns)} in its header")
        self.columns = columns


def finished_lines(path: Path) -> Iterator[str]:
    """The file's lines, newline kept, one at a time; a last line without one (torn) is left out."""
    try:
        f = open(path, newline="")  # noqa: SIM115 - closed below, also when the reader stops early
    except OSError as exc:
        raise RunFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    with f:
        try:
            for line in f:
                if line.endswith("\n"):
                    yield line
        except UnicodeDecodeError as exc:
            raise RunFileError(f"{path}: not text ({exc.reason})") from None


def iter_csv_rows(path: Path, numeric: Callable[[str], bool] | None = None,
                  required: Iterable[str] = ()) -> Iterator[dict[str, Any]]:
    """The finished rows of a CSV file with a header, as dicts, read as they are used: a run of
    millions of steps is summarised without holding it. A torn last row is left out.

    Cells of the columns ``numeric`` accepts become floats (an empty cell None); those of the
    ``required`` ones among them must be finite numbers. A cell that breaks this is an error
    naming the file, the line and the column.
    """
    required = tuple(required)
    reader = csv.DictReader(finished_lines(path))
    try:
        header = reader.fieldnames or []
        missing = [c for c in required if c not in header]
        if missing and header:
            raise MissingColumns(path, missing)
        columns = [c for c in header if numeric is not None and numeric(c)]
        for row in reader:
            if None in row or None in row.values():  # more or fewer cells than the header
                raise RunFileError(f"{path}: line {reader.line_num} does not have one cell for each of "
                                   f"its {len(header)} columns")
            for column in columns:
                row[column] = _number(row[column], path, reader.line_num, column, column in required)
            yield row
    except csv.Error as exc:
        raise RunFileError(f"{path}: line {reader.line_num}: {exc}") from None


def read_csv_rows(path: Path, numeric: Callable[[str], bool] | None = None,
                  required: Iterable[str] = ()) -> list[dict[str, Any]]:
    """All of :func:`iter_csv_rows` at once, for files known to be small."""
    return list(iter_csv_rows(path, numeric, required))


def _number(text: str, path: Path, line: int, column: str, required: bool) -> float | None:
    if text == "" and not required:
        return None
    try:
        value = float(text)
    except ValueError:
        value = None
    if value is None or (required and not math.isfinite(value)):
        raise RunFileError(f"{path}: line {line}, column {column}: {text[:40]!r} is not "
                           f"{'a finite number' if required else 'a number'}")
    return value


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """The finished records of a JSON-lines file; a torn last line is left out, a missing file is empty."""
    if not path.exists():
        return []
    records = []
    for number, line in enumerate(finished_lines(path), start=1):
        if not line.strip():
            continue
        try:
            records.append(json_text.loads(line))
        except ValueError as exc:
            raise RunFileError(f"{path}: line {number} is not JSON ({getattr(exc, 'msg', exc)})") from None
    return records
