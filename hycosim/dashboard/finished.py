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

from hycosim.core.lifetime import end_with
from hycosim.core.run_files import RunFileError, finished_lines
from hycosim.dashboard.changes import Watchers
from hycosim.server.report import RunDirError, envelope, read_columns, read_events, read_meta, summarise


def _column(run_dir: Path, port: str) -> tuple[array, array]:
    """``t`` and the port's values. Read by column index first, three times faster than the
    checked reader; at the first row that is not two plain numbers in a row of the header's
    length, the checked reader (hycosim.server.report.read_columns) reads it again and names the fault."""
    t, y = array("d"), array("d")
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


# The report's figures wait this long after a page first looks, for its first plots to be asked
# for: read after those, not before (a million rows take seconds each).
SUMMARY_DELAY_S = 3.0


class FinishedRun:
    def __init__(self, run_dir: Path):
        self.run_dir = run_dir
        self.meta = read_meta(run_dir)  # RunDirError: not a run directory
        self.switches = read_events(run_dir)
        self._ports = self._header()
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
        try:
            with open(path, newline="") as f:
                header = next(csv.reader(f), [])
        except (OSError, csv.Error, UnicodeDecodeError) as exc:
            raise RunDirError(f"{path}: cannot be read ({exc})") from None
        return [c for c in header if "." in c]

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
        nodes = [{"name": n, "attached": None, "host": None, "restarts": None,
                  "held_share": None if shares.get(n) is None or math.isnan(shares[n]) else shares[n],
                  "mean_arrival_ms": arrivals.get(n)} for n in names]
        m = self.meta
        series, problems = {}, []
        for port, points in ready.items():
            if isinstance(points, dict):
                problems.append({"error": points["error"], "closest": []})
            elif held.get(port) != (0, len(points[0])):
                series[port] = {"version": 0, "from": 0, "t": points[0], "y": points[1]}
        return {"source": "run", "state": "finished", "message": f"{m.status}" + (f": {m.reason}" if m.reason else ""),
                "project": self.run_dir.name, "run": self.run_dir.name, "step": m.steps or 0,
                "t": None, "mode": "", "steps_per_s": m.steps_per_s, "lateness_s": None, "nodes": nodes,
                "switches": self.switches, "dropped": m.dropped_frames, "coupling": m.coupling,
                "loading": sorted(set(select) & self._asked - set(ready)), "read_problems": problems,
                "summary_pending": summary is None and not problem, "summary_error": problem, "series": series}
