"""Reading a run directory back: the summary of ``hycosim report`` and the ``hycosim plot`` figure.

The timing file says, for every macro step, when each node's outputs arrived after the
release and which node arrived last — the one that held the barrier. Summing the wait
of each step onto its holder tells the user which simulator holds the others back.
"""

from __future__ import annotations

import heapq
import itertools
import json
import math
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from hycosim.core.hints import did_you_mean
from hycosim.core.run_files import RunFileError, iter_csv_rows, read_jsonl


class RunDirError(RuntimeError):
    """A path that is not a readable run directory."""


@dataclass
class RunSummary:
    """What ``hycosim report`` says of a run: its outcome and rate, who held the barrier and how long
    answers took, the slowest steps, the mode switches, the frames dropped, and the values that were not
    finite."""

    run_dir: str
    status: str
    reason: str
    steps: int
    wall_time_s: float | None
    steps_per_s: float | None
    holder_share: dict[str, float] = field(default_factory=dict)
    holder_steps: dict[str, int] = field(default_factory=dict)
    mean_arrival_ms: dict[str, float] = field(default_factory=dict)
    slowest_steps: list[dict[str, Any]] = field(default_factory=list)
    lateness: dict[str, float] | None = None
    mode_switches: list[dict[str, Any]] = field(default_factory=list)
    dropped_frames: dict[str, int] = field(default_factory=dict)
    non_finite: dict[str, dict[str, int | float]] = field(default_factory=dict)
    async_age_ms: dict[str, float] = field(default_factory=dict)
    wait_strategy: str = ""
    server_waits: dict[str, int] = field(default_factory=dict)
    ended_by: dict[str, Any] | None = None  # a node whose model ended the run: node, step, t, message
    coupling: str = ""  # the master algorithm (Jacobi or Gauss-Seidel, node rates)
    node_steps: dict[str, int] = field(default_factory=dict)  # steps each stepping node took (a slow node fewer)
    # Iterative coupling or the error-controlled step: what the meta says of them, how often each
    # step was taken (mean, max, steps taken more than once) and the step lengths used.
    iteration: str = ""
    step_control: str = ""
    takes: dict[str, float] | None = None
    step_sizes: dict[str, float] | None = None
    not_converged: dict[str, Any] | None = None


class EndedBy(BaseModel):
    """The node that ended the run with its own END: at which point and time, with its message."""

    node: str
    step: int
    t: float
    message: str = ""


class Iterations(BaseModel):
    """``meta.json``'s account of iterative coupling (server.retakes.IterationLog.record)."""

    model_config = ConfigDict(extra="allow")
    not_converged: int = 0
    worst: dict[str, Any] | None = None


class RunMeta(BaseModel):
    """The parts of ``meta.json`` a report reads; the recorder writes more."""

    model_config = ConfigDict(extra="allow")
    status: str = "?"
    reason: str = ""
    steps: int | None = None
    wall_time_s: float | None = None
    steps_per_s: float | None = None
    waitStrategy: str = ""
    dropped_frames: dict[str, int] = Field(default_factory=dict)
    non_finite: dict[str, dict[str, int | float]] = Field(default_factory=dict)
    server_waits: dict[str, int] = Field(default_factory=dict)
    ended_by: EndedBy | None = None
    coupling: str = ""
    iteration: str = ""
    step_control: str = ""
    iterations: Iterations | None = None
    samples_received: dict[str, int] = Field(default_factory=dict)  # asynchronous node → samples


class ModeSwitchRecord(BaseModel):
    """One line of ``events.jsonl`` (server.coordinator.ModeSwitch.as_record)."""

    model_config = ConfigDict(extra="allow", populate_by_name=True)
    step: int
    t: float
    event: str
    from_mode: str = Field(alias="from")
    to: str
    guard: str
    values: dict[str, Any]


def _problem(err: ValidationError) -> str:
    first = err.errors()[0]
    where = ".".join(str(part) for part in first["loc"])
    return f"{where}: {first['msg']}" if where else first["msg"]


def _timing_number(column: str) -> bool:
    return column in ("step", "t", "wait_s", "lateness_s", "takes") or column.startswith(("arrival_s:", "age_s:"))


def _rows(path: Path, numeric=None, required: tuple[str, ...] = ()) -> Iterator[dict[str, Any]]:
    try:
        yield from iter_csv_rows(path, numeric, required)
    except RunFileError as exc:
        raise RunDirError(str(exc)) from None


def read_meta(run_dir: Path) -> RunMeta:
    """A run directory's ``meta.json``, checked (:class:`RunMeta`); RunDirError naming the folder where
    it is missing or is not what a run writes."""
    path = run_dir / "meta.json"
    try:
        data = json.loads(path.read_bytes())
    except OSError:
        raise RunDirError(f"{run_dir}: not a run directory (no meta.json)") from None
    except json.JSONDecodeError as exc:
        raise RunDirError(f"{path}: unreadable ({exc.msg})") from None
    except UnicodeDecodeError as exc:
        raise RunDirError(f"{path}: not text ({exc.reason} at byte {exc.start})") from None
    except RecursionError:
        raise RunDirError(f"{path}: unreadable (nested too deeply)") from None
    if not isinstance(data, dict):
        raise RunDirError(f"{path}: not a run's metadata (a JSON object is expected, it holds a "
                          f"{type(data).__name__})")
    try:
        return RunMeta.model_validate(data)
    except ValidationError as err:
        raise RunDirError(f"{path}: not a run's metadata ({_problem(err)})") from None


class ScenarioRecord(BaseModel):
    """A line of ``events.jsonl`` saying a scenario's action took effect (server.scenario)."""

    model_config = ConfigDict(extra="allow")
    scenario: Literal["override", "release", "parameter"]
    target: str
    t_action: float
    t: float
    step: int


def _event_records(run_dir: Path) -> Iterator[tuple[str, dict[str, Any]]]:
    """Each line of ``events.jsonl`` checked as what it says it is: ("switch", a mode switch) or
    ("scenario", an action of the scenario that took effect)."""
    path = run_dir / "events.jsonl"
    try:
        records = read_jsonl(path)
    except RunFileError as exc:
        raise RunDirError(str(exc)) from None
    for number, record in enumerate(records, start=1):
        kind, model = (("scenario", ScenarioRecord) if type(record) is dict and "scenario" in record
                       else ("switch", ModeSwitchRecord))
        try:
            yield kind, model.model_validate(record).model_dump(by_alias=True)
        except ValidationError as err:
            what = "a scenario's action" if kind == "scenario" else "a mode switch"
            raise RunDirError(f"{path}: record {number} is not {what} ({_problem(err)})") from None


def read_events(run_dir: Path) -> list[dict[str, Any]]:
    """The mode switches of ``events.jsonl``, each checked against :class:`ModeSwitchRecord`."""
    return [record for kind, record in _event_records(run_dir) if kind == "switch"]


def read_scenario(run_dir: Path) -> list[dict[str, Any]]:
    """The scenario's actions that took effect, from ``events.jsonl`` (:class:`ScenarioRecord`)."""
    return [record for kind, record in _event_records(run_dir) if kind == "scenario"]


def summarise(run_dir: Path, slowest: int = 5) -> RunSummary:
    """The report of a run, read in one pass over its timing file (a long run is not held in memory)."""
    meta = read_meta(run_dir)
    waits: dict[str, float] = {}
    counts: dict[str, int] = {}
    arrival_sum: dict[str, float] = {}
    arrival_n: dict[str, int] = {}
    late = {"n": 0, "sum": 0.0, "max": 0.0, "over_1ms": 0}  # running figures: nothing kept per step
    age_sum: dict[str, float] = {}
    age_n: dict[str, int] = {}
    ranked: list[tuple[float, int, dict[str, Any]]] = []  # a heap of the slowest steps so far
    points = 0
    takes = {"n": 0, "sum": 0.0, "max": 0.0, "again": 0}
    sizes = {"n": 0, "min": math.inf, "max": 0.0}
    t_first = t_last = None
    for index, row in enumerate(_rows(run_dir / "timing.csv", _timing_number, required=("step", "t", "wait_s", "holder"))):
        points += 1
        t_row = row["t"]
        if index == 0:
            t_first = t_last = t_row
            continue  # step 0's wait is the start-up, not a macro step
        if t_last is not None and t_row is not None:
            h = t_row - t_last
            sizes.update(n=sizes["n"] + 1, min=min(sizes["min"], h), max=max(sizes["max"], h))
        t_last = t_row
        if row.get("takes") is not None:
            n = row["takes"]
            takes.update(n=takes["n"] + 1, sum=takes["sum"] + n, max=max(takes["max"], n), again=takes["again"] + (n > 1))
        holder, wait = row["holder"], row["wait_s"]
        waits[holder] = waits.get(holder, 0.0) + wait
        counts[holder] = counts.get(holder, 0) + 1
        for key, value in row.items():
            if key.startswith("arrival_s:") and value is not None:
                node = key.split(":", 1)[1]
                arrival_sum[node] = arrival_sum.get(node, 0.0) + value
                arrival_n[node] = arrival_n.get(node, 0) + 1
            elif key.startswith("age_s:") and value is not None:
                label = key.split(":", 1)[1]
                age_sum[label] = age_sum.get(label, 0.0) + value
                age_n[label] = age_n.get(label, 0) + 1
        if row.get("lateness_s") is not None:  # a column only a paced run fills
            x = row["lateness_s"]
            late.update(n=late["n"] + 1, sum=late["sum"] + x, max=max(late["max"], x),
                        over_1ms=late["over_1ms"] + (x > 0.001))
        # Ties go to the earlier step: the heap's least is the shortest wait, then the latest step.
        entry = (wait, -index, {"step": int(row["step"]), "t": row["t"], "wait_ms": 1000 * wait, "holder": holder})
        if len(ranked) < slowest:
            heapq.heappush(ranked, entry)
        elif slowest and entry[:2] > ranked[0][:2]:
            heapq.heapreplace(ranked, entry)
    total_wait = sum(waits.values())
    lateness = None
    if late["n"]:
        lateness = {"mean_ms": 1000 * late["sum"] / late["n"], "max_ms": 1000 * late["max"],
                    "late_steps": late["over_1ms"], "steps": late["n"]}
    # meta.json is rewritten when the run ends; one still "running" is live, or its server
    # was killed: the recorded points are the count then.
    steps = points if meta.status == "running" or meta.steps is None else meta.steps
    return RunSummary(
        run_dir=str(run_dir), status=meta.status, reason=meta.reason,
        steps=steps, wall_time_s=meta.wall_time_s, steps_per_s=meta.steps_per_s,
        holder_share={n: (w / total_wait if total_wait > 0 else math.nan) for n, w in sorted(waits.items())},
        holder_steps=dict(sorted(counts.items())),
        mean_arrival_ms={n: 1000 * arrival_sum[n] / arrival_n[n] for n in sorted(arrival_sum)},
        slowest_steps=[row for *_, row in sorted(ranked, key=lambda e: e[:2], reverse=True)],
        lateness=lateness, mode_switches=read_events(run_dir),
        dropped_frames=meta.dropped_frames, non_finite=meta.non_finite, async_age_ms={k: 1000 * age_sum[k] / age_n[k] for k in age_sum},
        wait_strategy=meta.waitStrategy, server_waits=meta.server_waits,
        ended_by=meta.ended_by.model_dump() if meta.ended_by else None,
        coupling=meta.coupling, node_steps=dict(sorted(arrival_n.items())),
        iteration=meta.iteration, step_control=meta.step_control,
        takes={"mean": takes["sum"] / takes["n"], "max": takes["max"], "steps_taken_again": takes["again"]}
        if takes["n"] else None,
        step_sizes={"min": sizes["min"], "max": sizes["max"], "mean": (t_last - t_first) / sizes["n"]}
        if meta.step_control and sizes["n"] else None,
        not_converged=meta.iterations.model_dump() if meta.iterations and meta.iterations.not_converged else None,
    )


def _number_or_text(value: Any) -> Any:
    try:
        return float(value)
    except (TypeError, ValueError):
        return value


PLOT_BUCKETS = 2000  # per line: about two points per pixel of the figure's width


def read_columns(run_dir: Path, ports: list[str]) -> dict[str, array]:
    """``t`` and the chosen ports as float arrays, in one pass over ``values.csv`` (nothing else
    of the run is held): the named ones (a cell that is not a number is an error), or with no
    names up to 8 that hold numbers only."""
    path = run_dir / "values.csv"
    rows = _rows(path, lambda c: c in ("step", "t"), required=("step", "t"))
    first = next(rows, None)
    if first is None:
        raise RunDirError(f"{path}: no macro step recorded (yet): nothing to plot")
    columns = list(first)
    unknown = [p for p in ports if p not in columns]
    if unknown:
        raise RunDirError(f"{run_dir}: no recorded port {', '.join(unknown)}{did_you_mean(unknown, columns[3:])} "
                          f"(recorded: {', '.join(columns[3:])})")
    # By default, the first 8 ports that read as numbers; one that turns out to hold text is left out.
    candidates = ports or [c for c in columns[3:] if isinstance(_number_or_text(first[c]), float)][:8]
    data = {c: array("d") for c in ("t", *candidates)}
    for row in itertools.chain([first], rows):
        data["t"].append(row["t"])
        for port in [c for c in data if c != "t"]:
            value = _number_or_text(row[port])
            if isinstance(value, float):
                data[port].append(value)
            elif ports:
                raise RunDirError(f"{path}: {port} is not a number at step {row['step']:g} "
                                  f"({str(value)[:40]!r}): only numeric ports can be plotted")
            else:
                del data[port]
    return data


def envelope(t: array, y: array, buckets: int = PLOT_BUCKETS) -> tuple[Any, Any]:
    """t and y thinned to each bucket's lowest and highest point, in time order: a figure a
    thousand pixels wide shows the same as with a million points, and draws in a moment."""
    import numpy as np

    tv, yv = np.frombuffer(t), np.frombuffer(y)
    if len(tv) <= 4 * buckets:
        return tv, yv
    edges = np.linspace(0, len(tv), buckets + 1).astype(int)
    keep: list[int] = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        part = yv[lo:hi]
        if np.isnan(part).all():
            keep.append(lo)  # one NaN keeps the gap a gap in the line
            continue
        keep.extend(sorted({lo + int(np.nanargmin(part)), lo + int(np.nanargmax(part))}))
    return tv[keep], yv[keep]


def read_steps(run_dir: Path) -> dict[str, array]:
    """Each macro step's end ``t``, length ``h`` and ``takes`` (how often it was taken, 1 where the
    run kept no count) from ``timing.csv``, in one pass."""
    data = {"t": array("d"), "h": array("d"), "takes": array("d")}
    last = None
    for row in _rows(run_dir / "timing.csv", _timing_number, required=("step", "t")):
        t = row["t"]
        if last is not None and t is not None:
            data["t"].append(t)
            data["h"].append(t - last)
            data["takes"].append(row.get("takes") or 1)
        last = t
    return data


def plot_run(run_dir: Path, ports: list[str], out: Path) -> Path:
    """Draw the chosen ``node.port`` columns over time with mode switches marked; below them, for
    a run whose master varied its step or took steps again, the step lengths and the takes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = read_columns(run_dir, ports)
    events = read_events(run_dir)
    meta = read_meta(run_dir)
    extra = []
    if meta.step_control or meta.iteration:
        steps = read_steps(run_dir)
        if meta.step_control and not meta.step_control.startswith("none") and len(steps["h"]):
            extra.append(("macro step (s)", steps["t"], steps["h"], True))
        if meta.iteration and not meta.iteration.startswith("none") or max(steps["takes"], default=1) > 1:
            extra.append(("takes of the step", steps["t"], steps["takes"], False))
    fig, axes = plt.subplots(1 + len(extra), 1, sharex=True, squeeze=False, figsize=(10, 5 + 2 * len(extra)),
                             gridspec_kw={"height_ratios": [3] + [1] * len(extra)})
    ax = axes[0][0]
    for port in (c for c in data if c != "t"):
        ax.plot(*envelope(data["t"], data[port]), label=port)
    for i, ev in enumerate(events):
        ax.axvline(ev["t"], color="red" if ev["to"] != "free" else "green", linestyle="--", linewidth=1,
                   label=f"{ev['from']}→{ev['to']}" if i < 6 else None)
    ax.set_title(f"{Path(run_dir).name}" + (f" ({meta.coupling})" if meta.coupling else ""))
    ax.legend(loc="best", fontsize=8)
    for (label, t, y, log), row in zip(extra, axes[1:]):
        row[0].step(*envelope(t, y), where="pre", linewidth=1)
        row[0].set_ylabel(label, fontsize=8)
        if log:
            row[0].set_yscale("log")
    for row in axes:
        row[0].grid(True, alpha=0.3)
    axes[-1][0].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
