"""Who turns the recorder's rows into text and writes ``values.csv`` and ``timing.csv``.

:class:`LocalRows` does it in the recorder's own thread: a distributed server keeps each
point's cells and formats the rows at each flush (every 0.1 s), together.

:class:`RowWriter` has a process of its own do it, for a run in one process: there the
master's thread steps every node itself, and the text of a row (a float's shortest repr is
about 0.45 µs; a row of a few ports costs more than a small FMU's step) would be on its
critical path. The master packs each row's cells (msgpack, a quarter of a microsecond) and
sends them down a pipe in batches; the writer, on another core, makes the same text
(:func:`~hycosim.master.record_files.joined_row`, the same formats) into the same files.
A cell msgpack cannot carry (an integer beyond 64 bits) goes as its row's text.

The guarantees of the records hold: what is sent is written as it arrives, and the master
sends at least at every flush (every 0.1 s); if the master's process dies (a crashed FMU
takes it down), the writer reads the end of its pipe, writes what came and exits; a write the
disk refuses is answered, and the master stops the run with the file's name at its next flush;
every wait for the writer has a timeout.
"""

from __future__ import annotations

import csv
import io
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Protocol

import msgpack

from hycosim.core.fd_wait import ready
from hycosim.master.record_files import ROW_FILES, RecordError, RecordFile, close_all, flush_all, joined_row, joined_rows

# What the master sends, each a msgpack array: [VALUES, cells], [TIMING, cells of the timing
# format], [TEXT, file name, text], [POSITIONS], [CUT, {file name: offset}], [CLOSE].
VALUES, TIMING, TEXT, POSITIONS, CUT, CLOSE = range(6)
# Rows a batch holds: small enough that the pipe takes it without waiting (about 100 bytes a
# row), large enough that a write is rare.
BATCH_ROWS = 256
ANSWER_TIMEOUT_S = 30.0


class Tables(Protocol):
    """Where the recorder's rows of ``values`` and ``timing`` go: CSV formatted here
    (:class:`LocalRows`), CSV formatted by a process of its own (:class:`RowWriter`), or
    Parquet (:class:`hycosim.master.parquet_tables.ParquetTables`). A position is what a
    checkpoint keeps of each table (a CSV file's byte offset, a Parquet table's row count)."""

    def values(self, cells: list[Any]) -> None:
        """A ``values`` row: step, t, mode, (stepped,) then every port's cell."""

    def timing(self, cells: tuple[Any, ...]) -> None:
        """A ``timing`` row of the fast format's cells."""

    def csv_row(self, name: str, cells: list[Any]) -> None:
        """A header, or a row whose cells may need quoting, of table ``name`` (by its CSV name)."""

    def flush(self, step: int | None = None) -> None:
        """Write what waits, as the format's rhythm has it; RecordError naming the file."""

    def positions(self) -> dict[str, int]:
        """Each table's position once everything taken is written."""

    def cut(self, positions: dict[str, int]) -> None:
        """Each table back to its position in ``positions`` (a checkpoint's)."""

    def close(self) -> list[str]:
        """Write the rest; the tables that could not be written, with why."""


class LocalRows:
    """The rows formatted in this thread and written at each flush. A row's cells wait until
    then and the rows are formatted together: one after another in a loop that runs hot, a
    row's text cost half what it cost made at each point amid the barrier's work.

    The cells wait in one flat list a file (a row's values, its width beside them; the timing
    rows all of the format's width), not a list or tuple a row: a row kept until the flush was
    an object the cyclic garbage collector walked at every young collection meanwhile, and a
    quarter of the server's collections were theirs. The timing rows of a flush are made by one
    ``%`` of the format repeated."""

    def __init__(self, run_dir: Path, timing_format: str | None, resume_at: dict[str, int], lead: int = 3):
        self._run_dir, self._lead = run_dir, lead
        self._waiting_values: list[Any] = []
        self._widths: list[int] = []  # of each row waiting in _waiting_values
        self._waiting_timing: list[Any] = []
        self._files: dict[str, RecordFile] = {}
        try:
            for name in ROW_FILES:
                self._files[name] = RecordFile(run_dir / name, resume_at.get(name))
        except OSError as exc:
            self.close()
            raise RecordError(f"cannot open the run's records in {run_dir}: {exc.strerror or exc}") from None
        self._values = self._files["values.csv"].buffer.write
        self._timing = self._files["timing.csv"].buffer.write
        self._timing_format = timing_format
        self._timing_width = timing_format.replace("%%", "").count("%") if timing_format is not None else 0
        self._csv = {name: csv.writer(f.buffer) for name, f in self._files.items()}

    def values(self, cells: list[Any]) -> None:
        """A ``values.csv`` row of cells none of which needs a quote."""
        self._waiting_values += cells
        self._widths.append(len(cells))

    def timing(self, cells: tuple[Any, ...]) -> None:
        """A ``timing.csv`` row: the cells of the timing format."""
        self._waiting_timing += cells

    def _format(self) -> None:
        """The rows waiting, into their files' buffers, in order."""
        if self._widths:
            flat, widths = self._waiting_values, self._widths
            width = widths[0]
            if widths.count(width) == len(widths):  # every row as wide: the rows by slices in C
                rows = [flat[i:i + width] for i in range(0, len(flat), width)]
            else:
                rows, i = [], 0
                for width in widths:
                    rows.append(flat[i:i + width])
                    i += width
            self._values(joined_rows(rows, self._lead))
            flat.clear()
            widths.clear()
        if self._waiting_timing:
            cells = self._waiting_timing
            if len(cells) % self._timing_width:
                raise RecordError(f"timing rows of {self._timing_width} cells were given {len(cells)} cells")
            self._timing((self._timing_format * (len(cells) // self._timing_width)) % tuple(cells))  # type: ignore[operator]
            cells.clear()

    def csv_row(self, name: str, cells: list[Any]) -> None:
        """A row of file ``name`` through csv.writer (a header, a row whose cells may need quotes)."""
        self._format()
        self._csv[name].writerow(cells)

    def flush(self, step: int | None = None) -> None:
        """Write what is buffered; RecordError naming the file if the disk refuses it."""
        self._format()
        flush_all(self._run_dir, self._files, step)

    def positions(self) -> dict[str, int]:
        """Where each file ends once everything is written (flushes); OSError if it cannot be."""
        self._format()
        return {name: f.position() for name, f in self._files.items()}

    def cut(self, positions: dict[str, int]) -> None:
        """Each file back to its offset in ``positions`` (a checkpoint's)."""
        self._format()
        for name, f in self._files.items():
            f.cut(positions[name])

    def close(self) -> list[str]:
        """Write the rest and close; the files that could not be written, with why."""
        self._format()  # nothing waits where the files did not all open
        return close_all(self._files)


class RowWriter:
    """The rows written by a process of its own (``python -m hycosim.master.row_writer``): see
    the module's text. Same methods as :class:`LocalRows`."""

    def __init__(self, run_dir: Path, timing_format: str | None, resume_at: dict[str, int], lead: int = 3,
                 timeout: float = ANSWER_TIMEOUT_S):
        self._run_dir, self._lead = run_dir, lead
        self._timeout = timeout
        spec = json.dumps({"run_dir": str(run_dir), "timing_format": timing_format, "resume_at": resume_at,
                           "lead": lead})
        # This hycosim, wherever the master found it (an installed wheel, a checkout on sys.path).
        home = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [home, os.environ.get("PYTHONPATH")])))
        # Its own session: a Ctrl-C at the terminal reaches the master, which closes the writer in order.
        self._proc = subprocess.Popen([sys.executable, "-m", "hycosim.master.row_writer", spec], env=env,
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, start_new_session=True)
        self._to, self._from = self._proc.stdin.fileno(), self._proc.stdout.fileno()  # type: ignore[union-attr]
        os.set_blocking(self._to, False)
        self._pack = msgpack.Packer().pack
        self._batch = bytearray()
        self._rows = 0
        self._replies = msgpack.Unpacker()
        self._answers: list[list[Any]] = []  # answers read (while sending rows) before they were waited for
        self._csv_text = io.StringIO()
        self._csv = csv.writer(self._csv_text)
        self._closed = False
        try:
            self._answer("opened")
        except RecordError:
            self._end()
            raise

    @property
    def pid(self) -> int:
        """The writer's process id."""
        return self._proc.pid

    def values(self, cells: list[Any]) -> None:
        """A ``values.csv`` row of cells none of which needs a quote."""
        try:
            self._batch += self._pack((VALUES, cells))
        except (OverflowError, TypeError, ValueError):  # an integer beyond 64 bits: the row as text
            self._batch += self._pack((TEXT, "values.csv", joined_row(cells, self._lead)))
        self._rows += 1
        if self._rows >= BATCH_ROWS:
            self._send(cells[0])  # a row's first cell is its step

    def timing(self, cells: tuple[Any, ...]) -> None:
        """A ``timing.csv`` row: the cells of the timing format."""
        self._batch += self._pack((TIMING, cells))

    def csv_row(self, name: str, cells: list[Any]) -> None:
        """A row of file ``name`` through csv.writer (a header, a row whose cells may need quotes),
        sent as its text."""
        self._csv.writerow(cells)
        self._batch += self._pack((TEXT, name, self._csv_text.getvalue()))
        self._csv_text.seek(0)
        self._csv_text.truncate()
        self._rows += 1
        if self._rows >= BATCH_ROWS:
            self._send()

    def flush(self, step: int | None = None) -> None:
        """Send what is batched; RecordError if the writer said a file was refused, or is gone."""
        self._send(step)

    def positions(self) -> dict[str, int]:
        """Where each file ends once everything sent is written."""
        self._batch += self._pack((POSITIONS,))
        self._send()
        return self._answer("positions")[1]

    def cut(self, positions: dict[str, int]) -> None:
        """Each file back to its offset in ``positions`` (a checkpoint's); what is batched is dropped."""
        self._batch = bytearray(self._pack((CUT, {name: positions[name] for name in ROW_FILES})))
        self._send()
        self._answer("cut")

    def close(self) -> list[str]:
        """Send the rest, have the writer write and close its files and exit; the files (or the
        writer) that could not be written, with why."""
        if self._closed:
            return []
        try:
            self._batch += self._pack((CLOSE,))
            self._write(bytes(self._batch))
            self._batch.clear()
            return list(self._answer("closed", past_errors=True)[1])
        except RecordError as exc:
            return [str(exc)]
        finally:
            self._end()

    def _send(self, step: int | None = None) -> None:
        data, self._rows = bytes(self._batch), 0
        self._batch.clear()
        self._write(data, step)
        self._take_replies(0.0, step)

    def _write(self, data: bytes, step: int | None = None) -> None:
        view = memoryview(data)
        while view:
            try:
                view = view[os.write(self._to, view):]
            except BlockingIOError:
                if not ready(self._to, write=True, timeout=self._timeout):
                    raise RecordError(f"the run's row writer (pid {self._proc.pid}) took no rows for "
                                      f"{self._timeout:g} s; {self._run_dir} holds what it wrote") from None
            except (BrokenPipeError, OSError):
                raise self._gone(step) from None

    def _take_replies(self, wait: float, step: int | None = None, past_errors: bool = False) -> None:
        """Keep the writer's answers that came within ``wait`` seconds; RecordError for a refused file."""
        if not ready(self._from, timeout=wait):
            return
        data = os.read(self._from, 1 << 16)
        if not data:
            raise self._gone(step)
        self._replies.feed(data)
        for reply in self._replies:
            if reply[0] != "error":
                self._answers.append(reply)
            elif not past_errors:
                _, name, why = reply
                raise RecordError.writing(self._run_dir, name, why, step)

    def _answer(self, kind: str, past_errors: bool = False) -> list[Any]:
        """Wait for the writer's answer ``kind`` (every wait has its end)."""
        deadline = time.monotonic() + self._timeout
        while True:
            for reply in self._answers:
                if reply[0] == kind:
                    self._answers.remove(reply)
                    return reply
            left = deadline - time.monotonic()
            if left <= 0:
                raise RecordError(f"the run's row writer (pid {self._proc.pid}) did not answer in "
                                  f"{self._timeout:g} s")
            self._take_replies(left, past_errors=past_errors)

    def _gone(self, step: int | None) -> RecordError:
        code = self._proc.poll()
        at = f" at step {step}" if step is not None else ""
        return RecordError(f"the run's row writer stopped{at} (exit code {code}); "
                           f"{self._run_dir} holds what it wrote")

    def _end(self) -> None:
        self._closed = True
        for pipe in (self._proc.stdin, self._proc.stdout):
            try:
                pipe.close()  # type: ignore[union-attr]
            except OSError:
                pass
        try:
            self._proc.wait(timeout=self._timeout)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()


def serve(run_dir: Path, timing_format: str | None, resume_at: dict[str, int], lead: int = 3) -> int:
    """The writer's side: rows from standard input into the files, answers on standard output,
    until CLOSE or the end of the input (the master's process is gone: what came is written)."""
    out = sys.stdout.buffer

    def answer(*reply: Any) -> None:
        try:
            out.write(msgpack.packb(reply))
            out.flush()
        except BrokenPipeError:  # the master is gone: what came is still written
            pass

    files: dict[str, RecordFile] = {}
    try:
        for name in ROW_FILES:
            files[name] = RecordFile(run_dir / name, resume_at.get(name))
    except OSError as exc:
        answer("error", name, exc.strerror or str(exc))
        return 1
    answer("opened")
    values, timing = files["values.csv"].buffer.write, files["timing.csv"].buffer.write
    unpacker = msgpack.Unpacker(strict_map_key=False)
    while data := os.read(0, 1 << 20):
        unpacker.feed(data)
        for kind, *body in unpacker:
            if kind == VALUES:
                cells, = body
                values(joined_row(cells, lead))
            elif kind == TIMING:
                cells, = body
                timing(timing_format % tuple(cells))  # type: ignore[operator]
            elif kind == TEXT:
                name, text = body
                files[name].buffer.write(text)
            elif kind == POSITIONS:
                ends = {}
                for name, f in files.items():
                    try:
                        ends[name] = f.position()
                    except OSError as exc:
                        answer("error", name, exc.strerror or str(exc))
                        break
                else:
                    answer("positions", ends)
            elif kind == CUT:
                offsets, = body
                for name, f in files.items():
                    f.cut(offsets[name])
                answer("cut")
            elif kind == CLOSE:
                answer("closed", close_all(files))
                return 0
        for name, f in files.items():
            try:
                f.flush()
            except OSError as exc:  # kept for the next flush; the master stops the run
                answer("error", name, exc.strerror or str(exc))
    close_all(files)
    return 0


if __name__ == "__main__":
    _spec = json.loads(sys.argv[1])
    sys.exit(serve(Path(_spec["run_dir"]), _spec["timing_format"], _spec["resume_at"], _spec["lead"]))
