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


def _read_csv(path: Path) -> list[dict[str, str]]:
    try:
        return read_csv_rows(path)
    except RunFileError as exc:
        raise RunDirError(str(exc)) from None


def read_meta(run_dir: Path) -> dict[str, Any]:
    path = run_dir / "meta.json"
    try:
        return json.loads(path.read_text())
    except OSError:
        raise RunDirError(f"{run_dir}: not a run directory (no meta.json)") from None
    except json.JSONDecodeError as exc:
        raise RunDirError(f"{path}: unreadable ({exc.msg})") from None


def read_events(run_dir: Path) -> list[dict[str, Any]]:
    try:
        return read_jsonl(run_dir / "events.jsonl")
    except RunFileError as exc:
        raise RunDirError(str(exc)) from None


def summarise(run_dir: Path, slowest: int = 5) -> RunSummary:
    meta = read_meta(run_dir)
    rows = _read_csv(run_dir / "timing.csv")
    waits: dict[str, float] = {}
    counts: dict[str, int] = {}
    arrival_sum: dict[str, float] = {}
    arrival_n: dict[str, int] = {}
    late: list[float] = []
    ages: dict[str, list[float]] = {}
    for row in rows[1:]:  # step 0's wait is the start-up, not a macro step
        holder, wait = row["holder"], float(row["wait_s"])
        waits[holder] = waits.get(holder, 0.0) + wait
        counts[holder] = counts.get(holder, 0) + 1
        for key, value in row.items():
            if key.startswith("arrival_s:") and value:
                node = key.split(":", 1)[1]
                arrival_sum[node] = arrival_sum.get(node, 0.0) + float(value)
                arrival_n[node] = arrival_n.get(node, 0) + 1
            elif key.startswith("age_s:") and value:
                ages.setdefault(key.split(":", 1)[1], []).append(float(value))
        if row["lateness_s"]:
            late.append(float(row["lateness_s"]))
    total_wait = sum(waits.values())
    ranked = sorted(rows[1:], key=lambda r: float(r["wait_s"]), reverse=True)[:slowest]
    lateness = None
    if late:
        lateness = {"mean_ms": 1000 * sum(late) / len(late), "max_ms": 1000 * max(late),
                    "late_steps": sum(1 for x in late if x > 0.001), "steps": len(late)}
    # meta.json is rewritten when the run ends; one still "running" is live, or its server
    # was killed: the recorded points are the count then.
    steps = len(rows) if meta.get("status") == "running" else int(meta.get("steps", len(rows)))
    return RunSummary(
        run_dir=str(run_dir), status=meta.get("status", "?"), reason=meta.get("reason", ""),
        steps=steps, wall_time_s=meta.get("wall_time_s"),
        steps_per_s=meta.get("steps_per_s"),
        holder_share={n: (w / total_wait if total_wait > 0 else math.nan) for n, w in sorted(waits.items())},
        holder_steps=dict(sorted(counts.items())),
        mean_arrival_ms={n: 1000 * arrival_sum[n] / arrival_n[n] for n in sorted(arrival_sum)},
        slowest_steps=[{"step": int(r["step"]), "t": float(r["t"]), "wait_ms": 1000 * float(r["wait_s"]),
                        "holder": r["holder"]} for r in ranked],
        lateness=lateness, mode_switches=read_events(run_dir),
        dropped_frames=meta.get("dropped_frames", {}) or {},
        async_age_ms={k: 1000 * sum(v) / len(v) for k, v in ages.items()},
        wait_strategy=str(meta.get("waitStrategy", "")),
        server_waits=meta.get("server_waits", {}) or {},
    )


def read_values(run_dir: Path) -> tuple[list[str], dict[str, list[Any]]]:
    rows = _read_csv(run_dir / "values.csv")
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
