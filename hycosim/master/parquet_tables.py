"""The run's tables as Parquet (``"recording": {"format": "parquet"}``, ``--record parquet``).

``values.parquet`` and ``timing.parquet`` hold what ``values.csv`` and ``timing.csv`` would,
column for column, typed: Int64 for Integer ports, bool for Boolean, float64 for Real, string,
binary. Each is a folder of parts (``part-<first row>.parquet``), one row group each, as Dask,
Spark and ``pyarrow.dataset`` write a table; ``pyarrow.parquet.read_table`` and pandas read the
folder as one table. A part is written whole under a temporary name and renamed, so a killed
server leaves only whole parts; the rows not yet in a part (at most PART_SECONDS of them) are
what such a kill loses, where the CSV loses at most FLUSH_EVERY_S.

A checkpoint's position in a table is its row count, and taking one writes a part: going back
to it deletes the parts after it, with no file read again.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from hycosim.core.schema import PortType, Project
from hycosim.master.record_files import RecordError

PART_SECONDS = 1.0  # a part at the first flush this long after the last one
PART_ROWS = 1 << 16  # or once this many rows wait
_PREFIX, _SUFFIX = "part-", ".parquet"


def table_dir(run_dir: Path, name: str) -> Path:
    """The Parquet folder that stands for the CSV file ``name`` (values.csv → values.parquet)."""
    return run_dir / (Path(name).stem + _SUFFIX)


def parts(folder: Path) -> list[tuple[int, Path]]:
    """The table's parts in row order, each with its first row; nothing else of the folder."""
    found = []
    for path in folder.glob(f"{_PREFIX}*{_SUFFIX}"):
        number = path.name[len(_PREFIX):-len(_SUFFIX)]
        if number.isdigit():
            found.append((int(number), path))
    return sorted(found)


def recorded_rows(run_dir: Path) -> int:
    """How many points a run directory's values table holds (CSV: its lines but the header)."""
    folder = table_dir(run_dir, "values.csv")
    if folder.is_dir():
        import pyarrow.parquet as pq

        return sum(pq.ParquetFile(path).metadata.num_rows for _, path in parts(folder))
    with open(run_dir / "values.csv", "rb") as f:
        return max(sum(1 for _ in f) - 1, 0)


def value_types(project: Project, marks_steps: bool) -> dict[str, Any]:
    """Each column of ``values.parquet`` and its Arrow type."""
    import pyarrow as pa

    of = {PortType.REAL: pa.float64(), PortType.INTEGER: pa.int64(), PortType.BOOLEAN: pa.bool_(),
          PortType.STRING: pa.string(), PortType.BINARY: pa.binary()}
    types = {"step": pa.int64(), "t": pa.float64(), "mode": pa.string()}
    if marks_steps:
        types["stepped"] = pa.string()
    for side in ("output", "input"):
        for n in project.nodeLists:
            for p in getattr(n, side):
                for column in p.columns(n.nodeName):
                    types[column] = of[p.type]
    return types


def timing_type(column: str) -> Any:
    """The Arrow type of a ``timing`` column: integers for the step and the takes, text for the holder,
    floats for the rest."""
    import pyarrow as pa

    if column in ("step", "takes"):
        return pa.int64()
    return pa.string() if column == "holder" else pa.float64()


def _converter(kind: Any) -> Any:
    """How a timing cell (a number, or the CSV's text of one; "" for none) becomes its column's type."""
    import pyarrow as pa

    convert = int if pa.types.is_integer(kind) else str if pa.types.is_string(kind) else float
    return lambda value: None if value is None or value == "" else convert(value)


class _Table:
    """One table: rows buffered, written as parts."""

    def __init__(self, folder: Path, types: dict[str, Any], resume_rows: int | None):
        self.folder, self.types = folder, types
        self.columns = list(types)
        self.converters = [_converter(types[c]) for c in self.columns]  # made once: a timing row is per point
        self.rows: list[list[Any]] = []
        self.written = 0
        self.last_part = time.monotonic()
        folder.mkdir(exist_ok=True)
        if resume_rows is not None:
            self.written = self._cut_files(resume_rows)

    def add(self, cells: list[Any]) -> None:
        self.rows.append(cells)

    def write_part(self) -> None:
        """The waiting rows as one part (one row group), written whole and renamed into place."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        self.last_part = time.monotonic()
        if not self.rows:
            return
        columns = list(zip(*self.rows))
        arrays = [pa.array(list(col), type=self.types[name]) for name, col in zip(self.columns, columns)]
        table = pa.Table.from_arrays(arrays, names=self.columns)
        final = self.folder / f"{_PREFIX}{self.written:012d}{_SUFFIX}"
        tmp = self.folder / f".{final.name}.tmp"
        pq.write_table(table, tmp, row_group_size=len(self.rows))
        os.replace(tmp, final)
        self.written += len(self.rows)
        self.rows = []

    def position(self) -> int:
        self.write_part()
        return self.written

    def cut(self, rows: int) -> None:
        """Back to ``rows`` rows: the waiting ones dropped, the parts after deleted."""
        self.rows = []
        self.written = self._cut_files(rows)

    def _cut_files(self, rows: int) -> int:
        import pyarrow.parquet as pq

        kept = 0
        for first, path in parts(self.folder):
            if first >= rows:
                path.unlink()
                continue
            count = pq.ParquetFile(path).metadata.num_rows
            if first + count > rows:  # a part across the point (not one a checkpoint made): rewritten shorter
                pq.write_table(pq.read_table(path).slice(0, rows - first), path)
                count = rows - first
            kept = max(kept, first + count)
        return kept


class ParquetTables:
    """``values.parquet`` and ``timing.parquet`` in ``run_dir``; the methods of
    :class:`~hycosim.master.row_writer.LocalRows`, cells given as the recorder has them."""

    def __init__(self, run_dir: Path, project: Project, marks_steps: bool, resume_at: dict[str, int],
                 timing_columns: list[str]):
        self._run_dir = run_dir
        try:
            import pyarrow  # noqa: F401 - the [parquet] extra; checked before the run, named here too
        except ImportError:
            raise RecordError("recording as Parquet needs pyarrow: pip install 'hycosim[parquet]'") from None
        try:
            self._values = _Table(table_dir(run_dir, "values.csv"), value_types(project, marks_steps),
                                  resume_at.get("values.csv"))
            self._timing = _Table(table_dir(run_dir, "timing.csv"), {c: timing_type(c) for c in timing_columns},
                                  resume_at.get("timing.csv"))
        except OSError as exc:
            raise RecordError(f"cannot open the run's records in {run_dir}: {exc.strerror or exc}") from None
        self._tables = {"values.csv": self._values, "timing.csv": self._timing}
        self._timing_names: list[str] = []

    def values(self, cells: list[Any]) -> None:
        """A ``values`` row: step, t, mode, (stepped,) then every port's value, typed."""
        self._values.rows.append(cells)

    def timing(self, cells: tuple[Any, ...]) -> None:
        """A ``timing`` row of the fast format's cells."""
        self.csv_row("timing.csv", list(cells))

    def csv_row(self, name: str, cells: list[Any]) -> None:
        """A timing row of the CSV's text; a header is passed over (the columns are known)."""
        table = self._tables[name]
        if table is self._values or cells == table.columns:
            return  # a header (the values' rows come through values)
        table.rows.append([convert(v) for convert, v in zip(table.converters, cells)])

    def flush(self, step: int | None = None) -> None:
        """A part of each table whose rows waited long enough or are many."""
        now = time.monotonic()
        for name, table in self._tables.items():
            if table.rows and (now - table.last_part >= PART_SECONDS or len(table.rows) >= PART_ROWS):
                self._write(name, table, step)

    def _write(self, name: str, table: _Table, step: int | None = None) -> None:
        try:
            table.write_part()
        except OSError as exc:
            raise RecordError.writing(self._run_dir, table.folder.name, exc, step) from None

    def positions(self) -> dict[str, int]:
        """Each table's rows once every waiting one is in a part (for a checkpoint)."""
        for name, table in self._tables.items():
            self._write(name, table)
        return {name: table.written for name, table in self._tables.items()}

    def cut(self, positions: dict[str, int]) -> None:
        """Each table back to its row count in ``positions`` (a checkpoint's)."""
        for name, table in self._tables.items():
            table.cut(positions[name])

    def close(self) -> list[str]:
        """Write the rest; the tables that could not be written, with why."""
        unwritten = []
        for name, table in self._tables.items():
            try:
                table.write_part()
            except Exception as exc:  # noqa: BLE001 - the end of every failure path: named, never raised
                unwritten.append(f"{table.folder.name}: {exc}")
        return unwritten

