"""Reading the line files of a run directory (``values.csv``, ``timing.csv``, ``events.jsonl``),
and the Parquet tables a run recorded as Parquet holds in place of the CSV files.

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


def parquet_twin(path: Path) -> Path | None:
    """The Parquet table (a folder of parts) a run recorded in place of the CSV file ``path``, if any."""
    twin = path.with_suffix(".parquet")
    return twin if path.suffix == ".csv" and not path.exists() and twin.is_dir() else None


def _csv_text(value: Any) -> str:
    """A typed Parquet cell as the CSV recorder writes it."""
    if value is None:
        return ""
    if type(value) is bool:
        return str(int(value))
    if type(value) is bytes:
        return value.hex() if len(value) <= 32 else f"<{len(value)} bytes>"
    return repr(value) if type(value) is float else str(value)


def table_lines(path: Path) -> Iterator[list[str]]:
    """The rows of the Parquet twin of CSV file ``path``, header first, each cell as the CSV's text."""
    import pyarrow.parquet as pq

    parts = _parts(path)
    header: list[str] | None = None
    for part in parts:
        try:
            table = pq.read_table(part)
        except Exception as exc:  # noqa: BLE001 - pyarrow's errors are of many kinds; the part is named
            raise RunFileError(f"{part}: not a Parquet table ({exc})") from None
        if header is None:
            header = table.column_names
            yield header
        elif table.column_names != header:
            raise RunFileError(f"{part}: its columns differ from those of {parts[0].name}")
        for batch in table.to_batches():
            columns = [batch.column(i).to_pylist() for i in range(batch.num_columns)]
            for row in zip(*columns):
                yield [_csv_text(v) for v in row]


def _parts(path: Path) -> list[Path]:
    folder = parquet_twin(path)
    return sorted(p for p in folder.glob("part-*.parquet") if p.name[5:-8].isdigit()) if folder else []


def table_header(path: Path) -> list[str]:
    """The columns of the Parquet twin of CSV file ``path`` (none if it has no part yet)."""
    import pyarrow.parquet as pq

    parts = _parts(path)
    try:
        return pq.ParquetFile(parts[0]).schema_arrow.names if parts else []
    except Exception as exc:  # noqa: BLE001 - pyarrow's errors are of many kinds; the part is named
        raise RunFileError(f"{parts[0]}: not a Parquet table ({exc})") from None


def table_last_row(path: Path) -> list[str]:
    """The last row of the Parquet twin of ``path``, cells as the CSV's text (empty if none)."""
    import pyarrow.parquet as pq

    parts = _parts(path)
    try:
        table = pq.read_table(parts[-1]) if parts else None
    except Exception:  # noqa: BLE001 - a part that cannot be read shows no last row
        return []
    if table is None or table.num_rows == 0:
        return []
    return [_csv_text(v) for v in table.slice(table.num_rows - 1).to_pylist()[0].values()]


def table_floats(path: Path, columns: list[str]) -> dict[str, list[float]]:
    """The ``columns`` of the Parquet twin of ``path`` as floats (a cell that is none, NaN);
    RunFileError naming the table for a column it lacks or one that holds no numbers."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    folder = parquet_twin(path)
    data: dict[str, list[float]] = {c: [] for c in columns}
    for part in _parts(path):
        try:
            table = pq.read_table(part, columns=columns)
        except Exception as exc:  # noqa: BLE001 - a missing column or a damaged part: named
            raise RunFileError(f"{folder}: {exc}") from None
        for c in columns:
            column = table.column(c)
            if not (pa.types.is_integer(column.type) or pa.types.is_floating(column.type)
                    or pa.types.is_boolean(column.type)):
                raise RunFileError(f"{folder}: {c} holds {column.type}, not numbers")
            data[c].extend(float("nan") if v is None else float(v) for v in column.to_pylist())
    return data


def iter_csv_rows(path: Path, numeric: Callable[[str], bool] | None = None,
                  required: Iterable[str] = ()) -> Iterator[dict[str, Any]]:
    """The finished rows of a CSV file with a header (or of its Parquet twin, cells as the CSV's
    text), as dicts, read as they are used: a run of millions of steps is summarised without
    holding it. A torn last row is left out.

    Cells of the columns ``numeric`` accepts become floats (an empty cell None); those of the
    ``required`` ones among them must be finite numbers. A cell that breaks this is an error
    naming the file, the line and the column.
    """
    required = tuple(required)
    if parquet_twin(path) is not None:
        lines = table_lines(path)
        header = next(lines, [])
        missing = [c for c in required if c not in header]
        if missing:
            raise MissingColumns(path.with_suffix(".parquet"), missing)
        columns = [c for c in header if numeric is not None and numeric(c)]
        for number, cells in enumerate(lines, start=2):
            row = dict(zip(header, cells))
            for column in columns:
                row[column] = _number(row[column], path.with_suffix(".parquet"), number, column, column in required)
            yield row
        return
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
