"""Reading the line files of a run directory (``values.csv``, ``timing.csv``, ``events.jsonl``).

The server appends one line per macro step or event and flushes often, so a run that was
killed (SIGKILL, power loss) leaves every line it finished on disk, and perhaps half of
the next one. Readers here keep the finished lines and leave out a last line that has no
newline: a torn write, not data. A malformed line anywhere else is an error naming the
file and the line, since nothing the server writes looks like that.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any


class RunFileError(RuntimeError):
    """A run file that cannot be read; the message names the file (and line)."""


def _finished_text(path: Path) -> str:
    try:
        text = path.read_text()
    except OSError as exc:
        raise RunFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise RunFileError(f"{path}: not text ({exc.reason} at byte {exc.start})") from None
    end = text.rfind("\n") + 1
    return text[:end]


def read_csv_rows(path: Path) -> list[dict[str, str]]:
    """The finished rows of a CSV file with a header, as dicts; a torn last row is left out."""
    reader = csv.DictReader(io.StringIO(_finished_text(path), newline=""))
    rows = []
    try:
        for row in reader:
            if None in row or None in row.values():  # more or fewer cells than the header
                raise RunFileError(f"{path}: line {reader.line_num} does not have one cell for each of "
                                   f"its {len(reader.fieldnames or [])} columns")
            rows.append(row)
    except csv.Error as exc:
        raise RunFileError(f"{path}: line {reader.line_num}: {exc}") from None
    return rows


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """The finished records of a JSON-lines file; a torn last line is left out, a missing file is empty."""
    if not path.exists():
        return []
    records = []
    for number, line in enumerate(_finished_text(path).splitlines(), start=1):
        if not line.strip():
            continue
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError as exc:
            raise RunFileError(f"{path}: line {number} is not JSON ({exc.msg})") from None
    return records
