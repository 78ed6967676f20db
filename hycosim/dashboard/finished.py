"""A finished (or stopped, or still written) run directory as the page shows it.

Nothing is read but the run's own record files, by their fixed names. The ports come from
``values.csv``'s header; a port's values are read in one pass over the file and thinned to
each bucket's lowest and highest point (as ``hycosim plot`` does), so that a run of a million
steps reaches the browser as a few thousand points. One reader thread reads, plots
first and then the report's figures (who held the barrier): the page is usable at once, and
each piece is pushed to it when read.
"""

from __future__ import annotations

import csv
import math
import multiprocessing
import os
import queue
import threading
from array import array
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from hycosim.core import json_text
from hycosim.core.guards import Guard, GuardError
from hycosim.core.lifetime import end_with
from hycosim.core.run_files import (RunFileError, finished_lines, parquet_twin, table_floats, table_header,
                                    table_last_row)
from hycosim.dashboard.changes import Watchers
from hycosim.master.report import RunDirError, envelope, read_columns, read_events, read_meta, summarise


def _column(run_dir: Path, port: str) -> tuple[array, array]:
    """``t`` and the port's values. Read by column index first, three times faster than the
    checked reader; at the first row that is not two plain numbers in a row of the header's
    length, the checked reader (hycosim.master.report.read_columns) reads it again and names the fault."""
    t, y = array("d"), array("d")
    if parquet_twin(run_dir / "values.csv") is not None:  # typed columns: read as they are
        try:
            data = table_floats(run_dir / "values.csv", ["t", port])
        except RunFileError as exc:
            raise RunDirError(str(exc)) from None
        return array("d", data["t"]), array("d", data[port])
    try:
        reader = csv.reader(finished_lines(run_dir / "values.csv"))
        header = next(reader)
        it, iy, width = header.index("t"), header.index(port), len(header)
        for row in reader:
            if len(row) != width:
                raise ValueError
            t.append(float(row[it]))
            y.append(float(row[iy]))
        return t, y
    except (ValueError, StopIteration, csv.Error, RunFileError):
        columns = read_columns(run_dir, [port])
        return columns["t"], columns[port]


def read_points(run_dir: Path, port: str) -> Any:
    """A port's ``[t, y]`` thinned for the page, or ``{"error": ...}`` (in the reader process)."""
    try:
        t, y = envelope(*_column(run_dir, port))
        return [[float(v) for v in t], [None if math.isnan(v) else float(v) for v in y]]
    except RunDirError as exc:
        return {"error": str(exc)}


def read_summary(run_dir: Path) -> tuple[dict[str, Any] | None, str]:
    """The report's figures the page shows, or why they cannot be had (in the reader process)."""
    try:
        s = summarise(run_dir)
    except RunDirError as exc:
        return None, str(exc)
    return {"holder_share": s.holder_share, "mean_arrival_ms": s.mean_arrival_ms, "node_steps": s.node_steps,
            "steps_per_s": s.steps_per_s, "steps": s.steps}, ""


_TAIL_BYTES = 1 << 20  # the last row is looked for in this much of values.csv's end
MAX_GUARDED = 8  # the guards' ports a finished run opens plotted, at most


def _float(cell: str) -> float | None:
    try:
        return float(cell)
    except ValueError:
        return None


# The report's figures wait this long after a page first looks, for its first plots to be asked
# for: read after those, not before (a million rows take seconds each).
SUMMARY_DELAY_S = 3.0


def last_row(path: Path, columns: list[str]) -> dict[str, Any]:
    """The last whole row of a run's ``values.csv`` (whose header is ``columns``): the run's t
    and mode where it ended, and each port's value there (a number where the cell is one). Read
    from the file's end, so that a run of a million rows opens as fast as a short one; empty
    where the file has no whole row (a String cell holding a newline reads as none)."""
    if parquet_twin(path) is not None:
        return _row_shown(table_last_row(path), columns)
    try:
        with open(path, "rb") as f:
            size = f.seek(0, os.SEEK_END)
            f.seek(max(0, size - _TAIL_BYTES))
            tail = f.read().decode("utf-8", errors="replace")
    except OSError:
        return {}
    lines = tail.split("\n")[:-1]  # the part after the last newline is torn (or empty)
    if len(lines) < (1 if size > _TAIL_BYTES else 2):
        return {}
    try:
        row = next(csv.reader([lines[-1]]))
    except csv.Error:
        return {}
    return _row_shown(row, columns)


def _row_shown(row: list[str], columns: list[str]) -> dict[str, Any]:
    """A last row's t, mode and port values, for the page (empty if it does not fit the header)."""
    if len(row) != len(columns) or row == columns:
        return {}
    cells = dict(zip(columns, row))
    t = _float(cells.get("t", ""))
    return {"t": t if t is not None and math.isfinite(t) else None, "mode": cells.get("mode", "")[:64],
            "values": {p: (v if (v := _float(cells[p])) is not None else cells[p][:80]) for p in columns if "." in p}}


def guard_ports(path: Path, ports: list[str]) -> list[str]:
    """The ``ports`` the project's events' guards name (when, until, rearm), in the order they
    first appear: what a finished run opens plotted. ``project.json`` is read as any file a
    user may have edited: anything that is not a guard over this run's ports is passed over."""
    try:
        doc = json_text.loads(path.read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return []
    events = doc.get("events") if type(doc) is dict else None
    found: list[str] = []
    for event in events if type(events) is list else []:
        for key in ("when", "until", "rearm"):
            text = event.get(key) if type(event) is dict else None
            if type(text) is not str:
                continue
            try:
                references = Guard(text).references
            except GuardError:
                continue
            found += [name for node, port in references if (name := f"{node}.{port}") in ports]
    return list(dict.fromkeys(found))[:MAX_GUARDED]


class FinishedRun:
    """A run directory as a dashboard source (see the module's text); RunDirError where the folder is
    not one."""

    def __init__(self, run_dir: Path):
        self.run_dir = run_dir
        self.meta = read_meta(run_dir)  # RunDirError: not a run directory
        self.switches = read_events(run_dir)
        self._columns = self._header()
        self._ports = [c for c in self._columns if "." in c]
        self._end = last_row(run_dir / "values.csv", self._columns)  # t, mode, each port's value where the run ended
        self._guarded = guard_ports(run_dir / "project.json", self._ports)
        self._series: dict[str, Any] = {}  # port → [t, y] thinned, or {"error": ...}
        self._asked: set[str] = set()
        self._lock = threading.Lock()
        self._summary: dict[str, Any] | None = None
        self._summary_error = ""
        self.version = 0  # counts the pieces read so far: the page is pushed each
        self.watchers = Watchers()  # the pages' feeds, woken at each
        # One reader, plots first: reading a million rows takes seconds, and the page is usable
        # meanwhile. It reads in a process of its own: a thread reading beside the web server's
        # would hold the interpreter and leave the page's requests waiting for seconds. The
        # reader ends with this process, however it ends.
        self._pool = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("forkserver"),
                                         initializer=end_with, initargs=(os.getpid(),))
        self._jobs: queue.PriorityQueue[tuple[int, str]] = queue.PriorityQueue()
        threading.Thread(target=self._work, name="dashboard-reader", daemon=True).start()
        self._timer: threading.Timer | None = None  # the figures' turn: set when a page first looks

    def _header(self) -> list[str]:
        path = self.run_dir / "values.csv"
        if parquet_twin(path) is not None:
            try:
                return table_header(path)
            except RunFileError as exc:
                raise RunDirError(str(exc)) from None
        try:
            with open(path, newline="") as f:
                header = next(csv.reader(f), [])
        except (OSError, csv.Error, UnicodeDecodeError) as exc:
            raise RunDirError(f"{path}: cannot be read ({exc})") from None
        return header

    def _work(self) -> None:
        while True:
            _, port = self._jobs.get()
            if port:
                self._load(port)
            else:
                self._summarise()
            with self._lock:
                self.version += 1
            self.watchers.notify()

    def _summarise(self) -> None:
        summary, problem = self._pool.submit(read_summary, self.run_dir).result()
        with self._lock:
            self._summary, self._summary_error = summary, problem

    def ports(self) -> list[str]:
        """The ports of the run's ``values.csv``, as ``node.port``."""
        return list(self._ports)

    def _load(self, port: str) -> None:
        points = self._pool.submit(read_points, self.run_dir, port).result()
        with self._lock:
            self._series[port] = points

    def snapshot(self, select: list[str], held: dict[str, tuple[int, int]] | None = None) -> dict[str, Any]:
        """The page's view; each selected port's thinned series once read, unless the page ``held`` it."""
        held = held or {}
        with self._lock:
            if self._timer is None:
                self._timer = threading.Timer(SUMMARY_DELAY_S, self._jobs.put, args=((1, ""),))
                self._timer.daemon = True
                self._timer.start()
            summary, problem = self._summary, self._summary_error
            for port in select:
                if port in self._ports and port not in self._asked:
                    self._asked.add(port)
                    self._jobs.put((0, port))
            ready = {p: self._series[p] for p in select if p in self._series}
        shares = (summary or {}).get("holder_share", {})
        arrivals = (summary or {}).get("mean_arrival_ms", {})
        names = list(dict.fromkeys(p.split(".", 1)[0] for p in self._ports))
        m = self.meta
        samples = m.samples_received
        nodes = [{"name": n, "attached": None, "host": None, "restarts": None,
                  "status": f"source: {samples[n]} samples" if n in samples else "stepped",
                  "held_share": None if shares.get(n) is None or math.isnan(shares[n]) else shares[n],
                  "mean_arrival_ms": arrivals.get(n)} for n in names]
        series, problems = {}, []
        for port, points in ready.items():
            if isinstance(points, dict):
                problems.append({"error": points["error"], "closest": []})
            elif held.get(port) != (0, len(points[0])):
                series[port] = {"version": 0, "from": 0, "t": points[0], "y": points[1]}
        return {"source": "run", "state": "finished", "message": f"{m.status}" + (f": {m.reason}" if m.reason else ""),
                "project": self.run_dir.name, "run": self.run_dir.name, "step": m.steps or 0,
                "t": self._end.get("t"), "mode": self._end.get("mode", ""), "values": self._end.get("values", {}),
                "guarded": self._guarded, "steps_per_s": m.steps_per_s, "lateness_s": None, "nodes": nodes,
                "switches": self.switches, "dropped": m.dropped_frames, "coupling": m.coupling,
                "loading": sorted(set(select) & self._asked - set(ready)), "read_problems": problems,
                "summary_pending": summary is None and not problem, "summary_error": problem, "series": series}
