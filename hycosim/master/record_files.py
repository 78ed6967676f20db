"""A record file written through its own buffer, and the text of a row.

Both the recorder (in the server's process) and the row writer (a process of its own, for a
run in one process) write ``values.csv`` and ``timing.csv`` this way, so the two give the
same bytes.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any, Mapping

import msgspec

#: The record files of every row: what a run in one process has a process of its own write.
ROW_FILES = ("values.csv", "timing.csv")


class RecordError(RuntimeError):
    """The run directory cannot be written (a full disk, a quota): the run stops."""

    @classmethod
    def writing(cls, run_dir: Path, name: str, exc: OSError | str, step: int | None = None) -> RecordError:
        """The error for file ``name`` of ``run_dir`` refused (``exc``: the OSError, or why)."""
        at = f" at step {step}" if step is not None else ""
        why = exc if isinstance(exc, str) else exc.strerror or exc
        return cls(f"cannot write the run's records{at}: {run_dir / name}: {why}")


# What msgspec writes for a cell otherwise than str() does: an exponent (e16 and e-5 for Python's
# e+16 and e-05), a number below 1e-4 in full (Python: with an exponent), null (None, NaN, the
# infinities), true and false, and a quoted string (bytes as base64). Anywhere else its text of
# an int or a float is Python's, digit for digit (tests/test_recorder.py holds it to that).
_NOT_PYTHONS = b'en"'  # and "0.0000"
_JSON = msgspec.json.Encoder()


def joined_row(cells: list[Any], lead: int = 3) -> str:
    """A CSV row of cells none of which can need a quote (numbers, identifiers): csv.writer's
    text of them (it writes str(), which is repr for floats), a fifth of its cost.

    The cells after the ``lead`` first (step, t, mode, and where a run marks them the nodes that
    stepped) are the ports' values: msgspec writes them in C, where its text is Python's (a
    float's shortest repr costs Python some 0.5 µs; a row of 16 such values took 10 µs, and
    0.7 in msgspec), and str() where it is not."""
    if len(cells) > lead:
        try:
            text = _JSON.encode(cells[lead:])
        except (TypeError, OverflowError, ValueError):  # a value msgspec does not write (a NumPy scalar)
            pass
        else:
            if len(text.translate(None, _NOT_PYTHONS)) == len(text) and b"0.0000" not in text:
                return f"{','.join(map(str, cells[:lead]))},{text[1:-1].decode()}\r\n"
    return ",".join(map(str, cells)) + "\r\n"


def joined_rows(rows: list[list[Any]], lead: int = 3) -> str:
    """The rows' text, as :func:`joined_row` makes each one's, in one msgspec call where it can.

    A row's lead cells are its step, its t and its mode (an identifier): msgspec writes the
    first two as str() does where the values' text is Python's, and the mode quoted, which is
    taken out. Where anything in the rows is not Python's text (an exponent, a quote left, a
    cell not a number) or a run marks the nodes that stepped, each row is made by
    :func:`joined_row`. A row's own text cost 2.4 µs at two nodes; in a batch of 500, 0.7."""
    if lead == 3 and len(rows) > 1:
        try:
            text = _JSON.encode(rows)
            bare = text
            for mode in {cells[2] for cells in rows}:
                quoted, plain = _JSON.encode(mode), str(mode).encode()
                for end in b",]":  # a row's mode before its values, or a row of no values
                    bare = bare.replace(b"," + quoted + bytes([end]), b"," + bytes([end]))
                    text = text.replace(b"," + quoted + bytes([end]), b"," + plain + bytes([end]))
        except (TypeError, OverflowError, ValueError, IndexError):  # a value msgspec does not write
            pass
        else:
            if (len(bare.translate(None, _NOT_PYTHONS)) == len(bare) and b"0.0000" not in bare
                    and bare.count(b"[") == len(rows) + 1 == bare.count(b"]")):
                return text[2:-2].replace(b"],[", b"\r\n").decode() + "\r\n"
    return "".join([joined_row(cells, lead) for cells in rows])


class RecordFile:
    """A file written through its own buffer: rows collect in ``buffer`` (written to directly,
    on the hot path) and go to the file at each flush; whatever a failed write (a full disk)
    left unwritten stays in memory for the next flush, in order. (A Python text file drops
    its pending text when the write under it fails: rows would go missing from the middle of
    the file.)"""

    def __init__(self, path: Path, resume_at: int | None = None):
        """Open ``path`` afresh, or (``resume_at``) the file a run wrote, cut back to that offset."""
        self.name = path.name
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | (0 if resume_at is not None else os.O_TRUNC), 0o644)
        self.buffer = io.StringIO()
        self._unwritten = b""
        if resume_at is not None:
            self.cut(resume_at)

    def position(self) -> int:
        """Where the file ends once what is buffered is written (flushes)."""
        self.flush()
        return os.lseek(self._fd, 0, os.SEEK_CUR)

    def cut(self, offset: int) -> None:
        """Drop everything after ``offset`` (the file and what is buffered): back to a checkpoint."""
        self.buffer.seek(0)
        self.buffer.truncate()
        self._unwritten = b""
        os.ftruncate(self._fd, offset)
        os.lseek(self._fd, offset, os.SEEK_SET)

    def flush(self) -> None:
        """Write what is buffered; OSError if the file refuses it (kept for the next flush)."""
        data = self._unwritten + self.buffer.getvalue().encode()
        self.buffer.seek(0)
        self.buffer.truncate()
        while data:
            try:
                written = os.write(self._fd, data)
            except OSError:
                self._unwritten = data
                raise
            data = data[written:]
        self._unwritten = b""

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._fd < 0

    def close(self) -> None:
        """Flush and close (the file is closed even when the flush fails)."""
        if self._fd < 0:
            return
        try:
            self.flush()
        finally:
            os.close(self._fd)
            self._fd = -1


def flush_all(run_dir: Path, files: Mapping[str, RecordFile], step: int | None = None) -> None:
    """Flush each of ``files`` (by name, in ``run_dir``); RecordError naming the first the disk refuses."""
    for name, f in files.items():
        try:
            f.flush()
        except OSError as exc:
            raise RecordError.writing(run_dir, name, exc, step) from None


def close_all(files: Mapping[str, RecordFile]) -> list[str]:
    """Close every one of ``files`` (by name); those that could not be written, with why."""
    unwritten = []
    for name, f in files.items():
        try:
            f.close()
        except OSError as exc:
            unwritten.append(f"{name}: {exc.strerror or exc}")
    return unwritten
