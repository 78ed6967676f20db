"""Reading a run directory back: the summary of ``hycosim report`` and the ``hycosim plot`` figure.

The timing file says, for every macro step, when each node's outputs arrived after the
release and which node arrived last — the one that held the barrier. Summing the wait
of each step onto its holder tells the user which simulator holds the others back.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from fmu_bridge.run_files import RunFileError, read_csv_rows, read_jsonl


class RunDirError(RuntimeError):
    """A path that is not a readable run directory."""


@dataclass
class RunSummary:
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
    async_age_ms: dict[str, float] = field(default_factory=dict)
    wait_strategy: str = ""
    server_waits: dict[str, int] = field(default_factory=dict)


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
    server_waits: dict[str, int] = Field(default_factory=dict)


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
    return column in ("step", "t", "wait_s", "lateness_s") or column.startswith(("arrival_s:", "age_s:"))


def _read_csv(path: Path, numeric=None, required: tuple[str, ...] = ()) -> list[dict[str, Any]]:
    try:
        return read_csv_rows(path, numeric, required)
    except RunFileError as exc:
        raise RunDirError(str(exc)) from None


def read_meta(run_dir: Path) -> RunMeta:
    path = run_dir / "meta.json"
    try:
        data = json.loads(path.read_bytes())
    except OSError:
        raise RunDirError(f"{run_dir}: not a run directory (no meta.json)") from None
    except json.JSONDecodeError as exc:
        raise RunDirError(f"{path}: unreadable ({exc.msg})") from None
    except UnicodeDecodeError as exc:
        raise RunDirError(f"{path}: not text ({exc.reason} at byte {exc.start})") from None
    if not isinstance(data, dict):
        raise RunDirError(f"{path}: not a run's metadata (a JSON object is expected, it holds a "
                          f"{type(data).__name__})")
    try:
        return RunMeta.model_validate(data)
    except ValidationError as err:
        raise RunDirError(f"{path}: not a run's metadata ({_problem(err)})") from None


def read_events(run_dir: Path) -> list[dict[str, Any]]:
    """The mode switches of ``events.jsonl``, each checked against :class:`ModeSwitchRecord`."""
    path = run_dir / "events.jsonl"
    try:
        records = read_jsonl(path)
    except RunFileError as exc:
        raise RunDirError(str(exc)) from None
    checked = []
    for number, record in enumerate(records, start=1):
        try:
            checked.append(ModeSwitchRecord.model_validate(record).model_dump(by_alias=True))
        except ValidationError as err:
            raise RunDirError(f"{path}: record {number} is not a mode switch ({_problem(err)})") from None
    return checked


def summarise(run_dir: Path, slowest: int = 5) -> RunSummary:
    meta = read_meta(run_dir)
    rows = _read_csv(run_dir / "timing.csv", _timing_number, required=("step", "t", "wait_s"))
    waits: dict[str, float] = {}
    counts: dict[str, int] = {}
    arrival_sum: dict[str, float] = {}
    arrival_n: dict[str, int] = {}
    late: list[float] = []
    ages: dict[str, list[float]] = {}
    stepped = rows[1:]  # step 0's wait is the start-up, not a macro step
    for row in stepped:
        holder, wait = row["holder"], row["wait_s"]
        waits[holder] = waits.get(holder, 0.0) + wait
        counts[holder] = counts.get(holder, 0) + 1
        for key, value in row.items():
            if key.startswith("arrival_s:") and value is not None:
                node = key.split(":", 1)[1]
                arrival_sum[node] = arrival_sum.get(node, 0.0) + value
                arrival_n[node] = arrival_n.get(node, 0) + 1
            elif key.startswith("age_s:") and value is not None:
                ages.setdefault(key.split(":", 1)[1], []).append(value)
        if row["lateness_s"] is not None:
            late.append(row["lateness_s"])
    total_wait = sum(waits.values())
    ranked = sorted(stepped, key=lambda r: r["wait_s"], reverse=True)[:slowest]
    lateness = None
    if late:
        lateness = {"mean_ms": 1000 * sum(late) / len(late), "max_ms": 1000 * max(late),
                    "late_steps": sum(1 for x in late if x > 0.001), "steps": len(late)}
    # meta.json is rewritten when the run ends; one still "running" is live, or its server
    # was killed: the recorded points are the count then.
    steps = len(rows) if meta.status == "running" or meta.steps is None else meta.steps
    return RunSummary(
        run_dir=str(run_dir), status=meta.status, reason=meta.reason,
        steps=steps, wall_time_s=meta.wall_time_s, steps_per_s=meta.steps_per_s,
        holder_share={n: (w / total_wait if total_wait > 0 else math.nan) for n, w in sorted(waits.items())},
        holder_steps=dict(sorted(counts.items())),
        mean_arrival_ms={n: 1000 * arrival_sum[n] / arrival_n[n] for n in sorted(arrival_sum)},
        slowest_steps=[{"step": int(r["step"]), "t": r["t"], "wait_ms": 1000 * r["wait_s"],
                        "holder": r["holder"]} for r in ranked],
        lateness=lateness, mode_switches=read_events(run_dir),
        dropped_frames=meta.dropped_frames, async_age_ms={k: 1000 * sum(v) / len(v) for k, v in ages.items()},
        wait_strategy=meta.waitStrategy, server_waits=meta.server_waits,
    )


def read_values(run_dir: Path) -> tuple[list[str], dict[str, list[Any]]]:
    """The columns of ``values.csv`` and their values: numbers where a cell reads as one, else text."""
    rows = _read_csv(run_dir / "values.csv", lambda c: c in ("step", "t"), required=("step", "t"))
    if not rows:
        return [], {}
    columns = list(rows[0].keys())
    data: dict[str, list[Any]] = {c: [] for c in columns}
    for row in rows:
        for c in columns:
            v = row[c]
            try:
                data[c].append(float(v))
            except (TypeError, ValueError):
                data[c].append(v)
    return columns, data


def plot_run(run_dir: Path, ports: list[str], out: Path) -> Path:
    """Draw the chosen ``node.port`` columns over time with mode switches marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns, data = read_values(run_dir)
    if not columns:
        raise RunDirError(f"{run_dir / 'values.csv'}: no macro step recorded (yet): nothing to plot")
    numeric = [c for c in columns[3:] if all(isinstance(v, float) for v in data[c])]
    chosen = ports or numeric[:8]
    unknown = [p for p in chosen if p not in columns]
    if unknown:
        raise RunDirError(f"{run_dir}: no recorded port {', '.join(unknown)} "
                          f"(recorded: {', '.join(columns[3:])})")
    for port in chosen:
        text = next((i for i, v in enumerate(data[port]) if not isinstance(v, float)), None)
        if text is not None:
            raise RunDirError(f"{run_dir / 'values.csv'}: {port} is not a number at step {data['step'][text]:g} "
                              f"({str(data[port][text])[:40]!r}): only numeric ports can be plotted")
    fig, ax = plt.subplots(figsize=(10, 5))
    for port in chosen:
        ax.plot(data["t"], data[port], label=port)
    for i, ev in enumerate(read_events(run_dir)):
        ax.axvline(ev["t"], color="red" if ev["to"] != "free" else "green", linestyle="--", linewidth=1,
                   label=f"{ev['from']}→{ev['to']}" if i < 6 else None)
    ax.set_xlabel("t (s)")
    ax.set_title(f"{Path(run_dir).name}")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
