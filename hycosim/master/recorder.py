"""The run directory: every routed value at every macro step, events, timing, every
asynchronous sample as received (``samples.jsonl``, which a replay plays back), metadata.

Rows are written as each macro step completes and flushed at least every 0.1 s of wall
time (a flush per step costs the barrier about a tenth of its rate), and always on close,
which every failure path of the server reaches: whatever happened before a failure is on
disk and readable. ``meta.json`` is rewritten with the outcome at the end. The text of the
rows is made here, or in a run in one process by a process of its own (server.row_writer).

A disk that fills up stops the run (RecordError) rather than the records going on with
gaps. So that the rows already taken and the outcome still reach the disk then, the run
directory holds a reserve file (RESERVE_BYTES) from the start, removed when the records
close: the space it frees is what the last buffered rows and ``meta.json`` are written into.
"""

from __future__ import annotations

import errno
import json
import time
from itertools import chain
from pathlib import Path
from typing import Any, Iterator

from hycosim.core.schema import PortType

from hycosim.core.config import LoadedProject
from hycosim.core.recordings import SAMPLES_FILE, encode_sample
from hycosim.master.observers import RecordedPoint, node_lists
from hycosim.master.record_files import RecordError, RecordFile, close_all, flush_all
from hycosim.master.parquet_tables import ParquetTables
from hycosim.master.row_writer import LocalRows, RowWriter, Tables

_flat = chain.from_iterable

__all__ = ["FLUSH_EVERY_S", "RESERVE_BYTES", "RESERVE_NAME", "RecordError", "Recorder"]


FLUSH_EVERY_S = 0.1
# Several times what is buffered when writing fails (three files' buffers, meta.json, the
# last log lines) and small beside any run's records.
RESERVE_BYTES = 256 * 1024
RESERVE_NAME = ".reserve"


def _cell(value: Any) -> Any:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, (bytes, bytearray)):
        return value.hex() if len(value) <= 32 else f"<{len(value)} bytes>"
    return value


def _cells(values: list[Any], arrays: list[bool]) -> Iterator[Any]:
    """A node's values as CSV cells: an array's elements one to a cell."""
    for value, array in zip(values, arrays):
        if array:
            yield from map(_cell, value)
        else:
            yield _cell(value)


def _typed_cells(values: list[Any], arrays: list[bool]) -> Iterator[Any]:
    """A node's values as typed cells (Parquet): an array's elements one to a cell."""
    for value, array in zip(values, arrays):
        if array:
            yield from value
        else:
            yield value


class Recorder:
    """Writes ``values.csv``, ``timing.csv`` (or their Parquet tables), ``events.jsonl``, ``samples.jsonl``
    and ``meta.json`` in ``run_dir``. The points come to it as to any observer of the run
    (master.observers): it is the first the master tells."""

    def __init__(self, run_dir: Path, loaded: LoadedProject, meta: dict[str, Any],
                 resume_at: dict[str, int] | None = None, rows_apart: bool = False, record_format: str = "csv"):
        """Open the run's files in ``run_dir`` (made by the caller); RecordError if they cannot be
        written (no space even for the reserve). ``resume_at``: go on with the files a run left
        there, each cut back to its offset (a checkpoint's), under the meta it wrote.
        ``rows_apart``: a process of its own writes the rows (:class:`RowWriter`: for a run in
        one process, where formatting them would hold up the master's thread). ``record_format``:
        the tables as ``csv`` or ``parquet`` (master.parquet_tables; typed, no text to make)."""
        self.run_dir = run_dir
        try:
            with open(run_dir / RESERVE_NAME, "wb") as reserve:
                reserve.write(bytes(RESERVE_BYTES))
        except OSError as exc:
            (run_dir / RESERVE_NAME).unlink(missing_ok=True)
            full = exc.errno in (errno.ENOSPC, errno.EDQUOT)
            raise RecordError(f"cannot start the run's records in {run_dir}: {exc.strerror or exc}" + (
                f" (a run directory needs {RESERVE_BYTES // 1024} KiB free to start)" if full else "")) from None
        project = loaded.project
        self._nodes = [n.nodeName for n in project.nodeLists]
        # Numbers go to the CSV as they are; only nodes with boolean or byte ports need _cell.
        # Parquet takes every type as it is: only arrays are spread over their columns.
        self.format = record_format
        parquet = record_format == "parquet"
        plain = tuple(PortType) if parquet else (PortType.REAL, PortType.INTEGER, PortType.STRING)
        self._spread = _typed_cells if parquet else _cells
        self._plain_out = {n.nodeName: all(p.type in plain and p.shape is None for p in n.output)
                           for n in project.nodeLists}
        self._plain_in = {n.nodeName: all(p.type in plain and p.shape is None for p in n.input)
                          for n in project.nodeLists}
        # Per node, which ports are arrays (one column per element): for the nodes not plain.
        self._arrays_out = {n.nodeName: [p.shape is not None for p in n.output] for n in project.nodeLists}
        self._arrays_in = {n.nodeName: [p.shape is not None for p in n.input] for n in project.nodeLists}
        self._stepping = [n.nodeName for n in project.stepping_nodes()]
        # A multi-rate run says at each point which nodes started a step there.
        self._marks_steps = loaded.coupling.multirate
        # A run that may take steps again says how often it took each.
        self._counts_takes = project.coSimulation.iterate is not None or project.coSimulation.stepControl is not None
        self._async_labels = [f"{r.dst_node}.{r.dst_port}" for r in loaded.routes
                              if project.node(r.src_node).asynchronous]
        # The rows are joined as text where no cell can need a CSV quote (names are identifiers,
        # numbers' text has no comma, only String ports hold free text): csv.writer's per-cell
        # work is a quarter of a row. The text is the same: csv.writer writes str(), repr for floats.
        self._joined = parquet or not any(p.type is PortType.STRING for n in project.nodeLists
                                          for p in (*n.output, *n.input))
        self._plain_nodes = [(n, self._plain_out[n], self._plain_in[n]) for n in self._nodes]
        # Where every port of every node is one cell (most runs), a row's values are the nodes'
        # lists end to end: two calls in C. A loop over the nodes on both sides took as long hot
        # and ran ten times the bytecode, which costs in a run where the server's code is cold
        # at each point (benchmarks/FINDINGS.md, 2026-12-04, seventh entry).
        self._lists = node_lists(self._nodes) if all(self._plain_out.values()) and all(self._plain_in.values()) \
            else None
        # A timing row of one release's arrivals, every stepping node's and no other's, in one format.
        self._timing_format = None if self._async_labels or self._counts_takes else \
            "%d,%r,%.9f,%s,%s" + ",%.9f" * len(self._stepping) + "\r\n"
        self._stepping_set = set(self._stepping)
        at = resume_at or {}
        try:
            self._events_file = RecordFile(run_dir / "events.jsonl", at.get("events.jsonl"))
            self._samples_file = RecordFile(run_dir / SAMPLES_FILE, at.get(SAMPLES_FILE))
        except OSError as exc:
            raise RecordError(f"cannot open the run's records in {run_dir}: {exc.strerror or exc}") from None
        timing_header = ["step", "t", "wait_s", "holder", "lateness_s",
                         *(f"arrival_s:{n}" for n in self._stepping),
                         *(f"age_s:{label}" for label in self._async_labels),
                         *(["takes"] if self._counts_takes else [])]
        self._rows: Tables
        if parquet:
            self._rows = ParquetTables(run_dir, project, self._marks_steps, at, timing_header)
        else:
            # The cells before the ports' values: step, t, mode, and the nodes that stepped.
            self._rows = (RowWriter if rows_apart else LocalRows)(run_dir, self._timing_format, at,
                                                                 lead=4 if self._marks_steps else 3)
        self._values_row, self._timing_cells = self._rows.values, self._rows.timing
        if resume_at is None:
            out_cols = [c for n in project.nodeLists for p in n.output for c in p.columns(n.nodeName)]
            in_cols = [c for n in project.nodeLists for p in n.input for c in p.columns(n.nodeName)]
            self._rows.csv_row("values.csv", ["step", "t", "mode", *(["stepped"] if self._marks_steps else []),
                                              *out_cols, *in_cols])
            self._rows.csv_row("timing.csv", timing_header)
        self._flushed = time.monotonic()
        self.meta = dict(meta)
        if resume_at is None:
            self.meta.update(status="running", started_at=time.time(), steps=0)
        else:
            self.meta.update(status="running")
        self.write_meta()
        self._files = {"events.jsonl": self._events_file, SAMPLES_FILE: self._samples_file}
        # Where the records stood at the checkpoint the run is going back to (its step, the positions).
        self._going_back: tuple[int, dict[str, int]] | None = None

    # --- an observer of the run's points (master.observers) --------------------------

    def step_complete(self, step: int, t: float, point: RecordedPoint) -> None:
        """Point ``step``: its row of values and its row of timing."""
        self.row(step, t, point.mode, point.outputs, point.inputs, point.stepped)
        self.timing(step, t, point.wait_s, point.holder, point.lateness_s, point.arrivals, point.ages, point.takes)

    def going_back(self, step: int, positions: dict[str, int]) -> None:
        """The run is going back to its checkpoint at point ``step``, where the record files
        ended at ``positions`` (the checkpoint's: it may come from another process's run)."""
        self._going_back = (step, positions)

    def state_restored(self, step: int, t: float) -> None:
        """Back at the checkpoint at point ``step``: every file cut to where it stood there."""
        if self._going_back is None or self._going_back[0] != step:
            raise RecordError(f"cannot cut the records in {self.run_dir} back to step {step}: "
                              "no checkpoint's positions were given for it")
        self.cut(self._going_back[1], steps=step)
        self._going_back = None

    def run_ended(self, status: str) -> None:
        """The run is over: the rest written, and the outcome (what the run put in ``meta`` with it)."""
        self.close(status)

    def row(self, step: int, t: float, mode: str, outputs: dict[str, list[Any]], inputs: dict[str, list[Any]],
            stepped: list[str] | None = None) -> None:
        """A ``values`` row: point ``step`` at ``t`` in ``mode``, every output and input as the point
        holds it (and, in a multi-rate run, the nodes that started a step there)."""
        cells: list[Any] = [step, t, mode]
        if self._marks_steps:
            cells.append(" ".join(stepped or ()))
        if self._lists is not None:
            cells += _flat(self._lists(outputs))
            cells += _flat(self._lists(inputs))
        else:
            for n, plain_out, _ in self._plain_nodes:
                cells.extend(outputs[n] if plain_out else self._spread(outputs[n], self._arrays_out[n]))
            for n, _, plain_in in self._plain_nodes:
                cells.extend(inputs[n] if plain_in else self._spread(inputs[n], self._arrays_in[n]))
        self.meta["steps"] = step + 1  # the row is taken even where its sending tells of a refused write
        if self._joined:
            self._values_row(cells)
        else:
            self._rows.csv_row("values.csv", cells)

    def sample(self, node: str, point: int, t: float, values: list[Any]) -> None:
        """A sample of asynchronous ``node`` received while point ``point`` was gathered (written
        with the next flush: a camera's samples cost the barrier no write of their own)."""
        self._samples_file.buffer.write(encode_sample(node, point, t, values))

    def timing(self, step: int, t: float, wait_s: float, holder: str, lateness_s: float | None,
               arrivals: dict[str, float], ages: dict[str, float | None], takes: int = 1) -> None:
        """One point's timing: of the step that ended there (``takes``: how often it was taken)."""
        if self._timing_format is not None and arrivals.keys() == self._stepping_set:
            self._timing_cells((step, t, wait_s, holder, "" if lateness_s is None else f"{lateness_s:.6f}",
                                *map(arrivals.__getitem__, self._stepping)))
        else:
            self._timing_row(step, t, wait_s, holder, lateness_s, arrivals, ages, takes)
        now = time.monotonic()
        if now - self._flushed >= FLUSH_EVERY_S:
            self.flush(step)
            self._flushed = now

    def _timing_row(self, step: int, t: float, wait_s: float, holder: str, lateness_s: float | None,
                    arrivals: dict[str, float], ages: dict[str, float | None], takes: int) -> None:
        self._rows.csv_row("timing.csv", [
            step, repr(t), f"{wait_s:.9f}", holder, "" if lateness_s is None else f"{lateness_s:.6f}",
            *(f"{arrivals[n]:.9f}" if n in arrivals else "" for n in self._stepping),
            *("" if ages.get(label) is None else f"{ages[label]:.6f}" for label in self._async_labels),
            *([takes] if self._counts_takes else [])])

    def positions(self, step: int | None = None) -> dict[str, int]:
        """Where each record file ends now (for a checkpoint); flushes them."""
        try:
            return {**self._rows.positions(), **{name: f.position() for name, f in self._files.items()}}
        except OSError as exc:
            raise RecordError.writing(self.run_dir, "the records", exc, step) from None

    def cut(self, positions: dict[str, int], steps: int) -> None:
        """Back to a checkpoint: every record file ends where ``positions`` says, ``steps`` rows recorded."""
        try:
            self._rows.cut(positions)
            for name, f in self._files.items():
                f.cut(positions[name])
        except OSError as exc:
            raise RecordError.writing(self.run_dir, "the records", exc) from None
        self.meta["steps"] = steps

    def flush(self, step: int | None = None) -> None:
        """Write what is buffered; RecordError naming the file if the disk refuses it."""
        self._rows.flush(step)
        flush_all(self.run_dir, self._files, step)

    def event(self, record: dict[str, Any]) -> None:
        """A line of ``events.jsonl`` (a mode switch, a scenario's action taking effect), written
        and flushed at once; RecordError naming the file where the disk refuses it."""
        try:
            self._events_file.buffer.write(json.dumps(record) + "\n")
            self._events_file.flush()
        except OSError as exc:
            raise RecordError.writing(self.run_dir, "events.jsonl", exc, record.get("step")) from None

    def write_meta(self) -> None:
        """Write ``meta.json`` whole, through a temporary file, so that a reader never sees half of it;
        RecordError naming the file where the disk refuses it."""
        tmp = self.run_dir / "meta.json.tmp"
        try:
            tmp.write_text(json.dumps(self.meta, indent=2, default=str))
            tmp.replace(self.run_dir / "meta.json")
        except OSError as exc:
            raise RecordError.writing(self.run_dir, "meta.json", exc) from None

    @property
    def closed(self) -> bool:
        """Whether the records are closed (the run's end wrote them)."""
        return self._events_file.closed

    def free_reserve(self) -> None:
        """Give back the reserve's space (at the start of a shutdown, so that the nodes' last
        words also find room); close does it too."""
        (self.run_dir / RESERVE_NAME).unlink(missing_ok=True)

    def close(self, status: str, **extra: Any) -> None:
        """Write the rest and the outcome. Never raises: it is the end of every failure path;
        a file that still cannot be written is named in meta.json, if that can be."""
        self.free_reserve()
        self.meta.update(status=status, finished_at=time.time(), **extra)
        self.meta["wall_time_s"] = self.meta["finished_at"] - self.meta["started_at"]
        unwritten = self._rows.close() + close_all(self._files)
        if unwritten:
            self.meta["unwritten"] = unwritten
        try:
            self.write_meta()
        except RecordError:
            pass
