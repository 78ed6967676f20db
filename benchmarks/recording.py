"""Recording: what a point's record costs the master as CSV and as Parquet, and the size on disk.

One synthetic project of N nodes with P outputs and P inputs each (50 value columns by
default), recorded for S points through the server's own Recorder (its ``row`` and
``timing`` per point, then ``close``): as CSV formatted in the master's thread (a distributed
run), as CSV handed to a row writer process (a run in one process), and as Parquet (typed, a
part a second). Rounds are interleaved; the medians are reported with each format's ratio to
CSV in the master's thread, measured in the same run.

    python benchmarks/recording.py [--steps 100000] [--nodes 5] [--ports 5] [--repeat 3] [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import _table

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from hycosim.core.config import load_project  # noqa: E402
from hycosim.master.recorder import Recorder  # noqa: E402

FORMATS = {"csv": ("csv", False), "csv, rows in a process of their own": ("csv", True), "parquet": ("parquet", False)}


def _project(folder: Path, nodes: int, ports: int) -> Path:
    doc = {"projectName": "rec", "nodeNum": nodes, "coSimulation": {"stepSize": 0.001, "stopTime": 1.0},
           "nodeLists": [{"nodeName": f"n{i}", "UID": i + 1, "model": "gain",
                          "input": [f"u{j}" for j in range(ports)], "output": [f"y{j}" for j in range(ports)]}
                         for i in range(nodes)]}
    path = folder / "rec.json"
    path.write_text(json.dumps(doc))
    return path


def _size(run_dir: Path) -> int:
    """The bytes of the two tables: values and timing, as CSV files or Parquet folders."""
    found = [run_dir / "values.csv", run_dir / "timing.csv",
             *(run_dir / "values.parquet").glob("*.parquet"), *(run_dir / "timing.parquet").glob("*.parquet")]
    return sum(p.stat().st_size for p in found if p.is_file())


def measure(loaded, folder: Path, fmt: str, apart: bool, steps: int) -> tuple[float, int]:
    """Seconds a point costs the master (row, timing and the share of close), and the tables' bytes."""
    run_dir = folder / f"{fmt}-{apart}-{time.perf_counter_ns()}"
    run_dir.mkdir()
    recorder = Recorder(run_dir, loaded, {}, rows_apart=apart, record_format=fmt)
    names = [n.nodeName for n in loaded.project.nodeLists]
    width = len(loaded.project.nodeLists[0].output)
    outputs = {n: [0.0] * width for n in names}
    inputs = {n: [0.0] * width for n in names}
    arrivals = {n: 0.0 for n in names}
    started = time.perf_counter()
    for k in range(steps):
        t = k * 0.001
        for i, n in enumerate(names):  # new values each point, as a run has
            outputs[n] = [t * (i + j + 1) for j in range(width)]
            inputs[n] = [t / (i + j + 1) for j in range(width)]
        recorder.row(k, t, "free", outputs, inputs)
        recorder.timing(k, t, 1e-5, names[-1], None, arrivals, {})
    recorder.close("completed")
    took = time.perf_counter() - started
    return took / steps, _size(run_dir)


def main() -> None:
    """Measure what a point's record costs as CSV and as Parquet, and the files' sizes; print the
    figures (``--json``: one object)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=100_000)
    ap.add_argument("--nodes", type=int, default=5)
    ap.add_argument("--ports", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        loaded = load_project(_project(folder, args.nodes, args.ports))
        # The same loop with nothing recorded: what making the values costs, taken off each.
        base: list[float] = []
        times: dict[str, list[float]] = {name: [] for name in FORMATS}
        sizes: dict[str, int] = {}
        for _ in range(args.repeat):
            started = time.perf_counter()
            names = [n.nodeName for n in loaded.project.nodeLists]
            for k in range(args.steps):
                t = k * 0.001
                for i, n in enumerate(names):
                    [t * (i + j + 1) for j in range(args.ports)], [t / (i + j + 1) for j in range(args.ports)]
            base.append((time.perf_counter() - started) / args.steps)
            for name, (fmt, apart) in FORMATS.items():
                seconds, size = measure(loaded, folder, fmt, apart, args.steps)
                times[name].append(seconds)
                sizes[name] = size
    loop = statistics.median(base)
    cost = {name: max(statistics.median(v) - loop, 0.0) for name, v in times.items()}
    columns = 3 + 2 * args.nodes * args.ports
    result = {"steps": args.steps, "columns": columns, "us_per_point": {k: 1e6 * v for k, v in cost.items()},
              "bytes": sizes, "vs_csv": {k: cost[k] / cost["csv"] for k in cost},
              "size_vs_csv": {k: sizes[k] / sizes["csv"] for k in sizes}}
    if args.json:
        print(json.dumps(result, indent=1))
    else:
        for name in FORMATS:
            print(f"{name:38s} {1e6 * cost[name]:7.2f} µs a point ({cost[name] / cost['csv']:.2f}× csv), "
                  f"{sizes[name] / 1e6:8.2f} MB ({sizes[name] / sizes['csv']:.2f}× csv)")
    table = _table.Table(
        f"The master's time a point's record takes, and the tables on disk: {args.steps:,} points × "
        f"{columns} columns (values.csv's), medians of {args.repeat} interleaved rounds:",
        ["format", "µs a point", "time × csv", "MB on disk", "size × csv"],
        [[name, f"{1e6 * cost[name]:.2f}", f"{cost[name] / cost['csv']:.2f}", f"{sizes[name] / 1e6:.2f}",
          f"{sizes[name] / sizes['csv']:.2f}"] for name in FORMATS],
        "In a run in one process the CSV's text is made by a process of its own, off the master's "
        "thread; Parquet takes the values as they are and makes no text.")
    _table.write(args.table, table)


if __name__ == "__main__":
    main()
