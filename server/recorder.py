"""The run directory: every routed value at every macro step, events, timing, metadata.

Rows are written as each macro step completes and flushed at least every 0.1 s of wall
time (a flush per step costs the barrier about a tenth of its rate), and always on close,
which every failure path of the server reaches: whatever happened before a failure is on
disk and readable. ``meta.json`` is rewritten with the outcome at the end.
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path
from typing import Any

from fmu_bridge.config import LoadedProject, PortType


FLUSH_EVERY_S = 0.1


def _cell(value: Any) -> Any:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, (bytes, bytearray)):
        return value.hex() if len(value) <= 32 else f"<{len(value)} bytes>"
    return value


class Recorder:
    """Writes ``values.csv``, ``timing.csv``, ``events.jsonl`` and ``meta.json`` in ``run_dir``."""

    def __init__(self, run_dir: Path, loaded: LoadedProject, meta: dict[str, Any]):
        self.run_dir = run_dir
        run_dir.mkdir(parents=True, exist_ok=True)
        project = loaded.project
        self._nodes = [n.nodeName for n in project.nodeLists]
        # Numbers go to the CSV as they are; only nodes with boolean or byte ports need _cell.
        plain = (PortType.REAL, PortType.INTEGER, PortType.STRING)
        self._plain_out = {n.nodeName: all(p.type in plain for p in n.output) for n in project.nodeLists}
        self._plain_in = {n.nodeName: all(p.type in plain for p in n.input) for n in project.nodeLists}
        self._stepping = [n.nodeName for n in project.stepping_nodes()]
        self._async_labels = [f"{r.dst_node}.{r.dst_port}" for r in loaded.routes
                              if project.node(r.src_node).asynchronous]
        self._values_file = open(run_dir / "values.csv", "w", newline="")  # noqa: SIM115
        self._values = csv.writer(self._values_file)
        out_cols = [f"{n.nodeName}.{p.name}" for n in project.nodeLists for p in n.output]
        in_cols = [f"{n.nodeName}.{p.name}" for n in project.nodeLists for p in n.input]
        self._values.writerow(["step", "t", "mode", *out_cols, *in_cols])
        self._timing_file = open(run_dir / "timing.csv", "w", newline="")  # noqa: SIM115
        self._timing = csv.writer(self._timing_file)
        self._timing.writerow(["step", "t", "wait_s", "holder", "lateness_s",
                               *(f"arrival_s:{n}" for n in self._stepping),
                               *(f"age_s:{label}" for label in self._async_labels)])
        self._events_file = open(run_dir / "events.jsonl", "w")  # noqa: SIM115
        self._flushed = time.monotonic()
        self.meta = dict(meta)
        self.meta.update(status="running", started_at=time.time(), steps=0)
        self.write_meta()

    def row(self, step: int, t: float, mode: str, outputs: dict[str, list[Any]], inputs: dict[str, list[Any]]) -> None:
        cells: list[Any] = [step, repr(t), mode]
        for n in self._nodes:
            cells.extend(outputs[n] if self._plain_out[n] else map(_cell, outputs[n]))
        for n in self._nodes:
            cells.extend(inputs[n] if self._plain_in[n] else map(_cell, inputs[n]))
        self._values.writerow(cells)
        self.meta["steps"] = step + 1

    def timing(self, step: int, t: float, wait_s: float, holder: str, lateness_s: float | None,
               arrivals: dict[str, float], ages: dict[str, float | None]) -> None:
        self._timing.writerow([
            step, repr(t), f"{wait_s:.9f}", holder, "" if lateness_s is None else f"{lateness_s:.6f}",
            *(f"{arrivals[n]:.9f}" if n in arrivals else "" for n in self._stepping),
            *("" if ages.get(label) is None else f"{ages[label]:.6f}" for label in self._async_labels)])
        now = time.monotonic()
        if now - self._flushed >= FLUSH_EVERY_S:
            self.flush()
            self._flushed = now

    def flush(self) -> None:
        for f in (self._values_file, self._timing_file, self._events_file):
            f.flush()

    def event(self, record: dict[str, Any]) -> None:
        self._events_file.write(json.dumps(record) + "\n")
        self._events_file.flush()

    def write_meta(self) -> None:
        tmp = self.run_dir / "meta.json.tmp"
        tmp.write_text(json.dumps(self.meta, indent=2, default=str))
        tmp.replace(self.run_dir / "meta.json")

    @property
    def closed(self) -> bool:
        return self._values_file.closed

    def close(self, status: str, **extra: Any) -> None:
        self.meta.update(status=status, finished_at=time.time(), **extra)
        self.meta["wall_time_s"] = self.meta["finished_at"] - self.meta["started_at"]
        for f in (self._values_file, self._timing_file, self._events_file):
            f.close()
        self.write_meta()
