"""One run of a sweep, as a worker takes it: the project with the variant's parameters set,
run in process through ``hycosim.open`` to its stop time (or its deadline), and its row: the
parameters, how it ended, its rate, the metrics asked for. Only what a run needs is imported."""

from __future__ import annotations

import csv
import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hycosim.core import json_text
from hycosim.ensemble.variants import SweepError

REDUCTIONS = ("final", "min", "max", "mean")


@dataclass(frozen=True)
class Metric:
    """``port`` (node.port) reduced over the run's points by ``how`` (final, min, max or mean)."""

    port: str
    how: str

    @property
    def column(self) -> str:
        """The metric's column in the sweep's table, ``node.port:how``."""
        return f"{self.port}:{self.how}"


def parse_metric(text: str) -> Metric:
    """A ``--metric`` as written (``node.port:final``, ``:min``, ``:max`` or ``:mean``); SweepError
    naming it otherwise."""
    port, _, how = text.rpartition(":")
    if not port or "." not in port or how not in REDUCTIONS:
        raise SweepError(f"--metric {text!r}: write node.port:final, :min, :max or :mean")
    return Metric(port, how)


def with_parameters(doc: dict[str, Any], values: dict[str, Any]) -> dict[str, Any]:
    """The project ``doc`` with each ``node.param`` of ``values`` among its node's parameters."""
    nodes = []
    for node in doc["nodeLists"]:
        mine = {key.split(".", 1)[1]: v for key, v in values.items() if key.split(".", 1)[0] == node["nodeName"]}
        nodes.append({**node, "parameters": {**node.get("parameters", {}), **mine}} if mine else node)
    return {**doc, "nodeLists": nodes}


def _reduce(column: list[float], how: str) -> float:
    if not column:
        return math.nan
    if how == "final":
        return column[-1]
    if how == "min":
        return min(column)
    if how == "max":
        return max(column)
    return sum(column) / len(column)


def metrics_of(run_dir: Path, metrics: list[Metric]) -> dict[str, float]:
    """Each metric over the run's values.csv (NaN where the run recorded no point or no number)."""
    columns: dict[str, list[float]] = {m.port: [] for m in metrics}
    path = run_dir / "values.csv"
    if path.is_file() and metrics:
        try:
            with open(path, newline="") as f:
                for row in csv.DictReader(f):
                    for port, column in columns.items():
                        try:
                            column.append(float(row[port]))
                        except (KeyError, TypeError, ValueError):
                            pass
        except (OSError, UnicodeDecodeError, csv.Error):  # a row past the csv module's field limit: what was read
            pass
    return {m.column: _reduce(columns[m.port], m.how) for m in metrics}


def _rate(run_dir: Path, steps: int, wall_s: float) -> float:
    """The run's own steps a second (its loop's, as meta.json says), else over the whole call."""
    try:
        meta = json_text.loads((run_dir / "meta.json").read_bytes())
    except (OSError, ValueError):
        meta = None
    rate = meta.get("steps_per_s") if type(meta) is dict else None
    if type(rate) in (int, float) and math.isfinite(rate):
        return float(rate)
    return steps / wall_s if wall_s > 0 else math.nan


def run_variant(doc: dict[str, Any], index: int, values: dict[str, Any], out: str, timeout: float | None,
                metrics: list[Metric]) -> dict[str, Any]:
    """Run variant ``index`` of ``doc`` (paths absolute) with ``values`` under ``out``/runs and
    return its row; a run that fails is a row saying so, never an exception."""
    import hycosim

    row: dict[str, Any] = {"run": index, **values, "outcome": "failed", "message": "", "steps_per_s": math.nan,
                           "wall_s": math.nan, "run_dir": ""}
    began = time.monotonic()
    project = with_parameters(doc, values)
    stop = float(project.get("coSimulation", {}).get("stopTime", 0.0))
    try:
        with hycosim.open(project, runs_dir=Path(out) / "runs" / f"{index:05d}") as sim:
            row["run_dir"] = str(sim.run_dir)
            # The deadline stops the run from another thread: a step may take any time.
            timer = threading.Timer(timeout, sim.stop) if timeout is not None else None
            if timer is not None:
                timer.daemon = True
                timer.start()
            try:
                sim.run_until(stop)
            finally:
                if timer is not None:
                    timer.cancel()
            steps, late = sim.step_count, timer is not None and timer.finished.is_set() and not sim.ended
        outcome = sim.outcome
        row["outcome"], row["message"] = outcome.status, outcome.message
        if timeout is not None and (late or (outcome.status == "stopped" and time.monotonic() - began > timeout)):
            row["outcome"], row["message"] = "timeout", f"still running after {timeout:g} s: stopped at t={sim.time:g} s"
        row["wall_s"] = time.monotonic() - began
        row["steps_per_s"] = _rate(Path(row["run_dir"]), steps, row["wall_s"])
    except hycosim.SimulationError as exc:
        row["message"] = str(exc)
        row["wall_s"] = time.monotonic() - began
    row.update(metrics_of(Path(row["run_dir"]), metrics) if row["run_dir"] else {m.column: math.nan for m in metrics})
    return row
