"""Sweeps on Dask: runs a second with 2 workers against 1, and the time a run takes through a
sweep against a plain loop of ``hycosim.open`` in one process (what Dask adds per run).

The system is benchmarks/inprocess.py's three FMUs (benchmarks/_small_fmus.py: Dahlquist →
feedthrough, Van der Pol), ``--runs`` variants of the Dahlquist's k and the oscillator's mu
drawn from a seeded generator, each ``--steps`` macro steps. The plain loop runs the same
variants one after another in this process; each sweep starts its own LocalCluster (its start
is counted: a user waits for it too).

    python benchmarks/sweep.py [--runs 200] [--steps 200] [--json] [--table FILE]
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import _table  # noqa: E402
from _small_fmus import write_package  # noqa: E402


def plain_loop(project: Path, variants: list[dict], out: Path) -> float:
    """Seconds for the variants run one after another through hycosim.open in this process."""
    import hycosim
    from hycosim.api import absolute_paths
    from hycosim.ensemble.runs import with_parameters

    doc = absolute_paths(json.loads(project.read_text()), project.parent)
    stop = doc["coSimulation"]["stopTime"]
    began = time.perf_counter()
    for i, values in enumerate(variants):
        with hycosim.open(with_parameters(doc, values), runs_dir=out / f"{i:05d}") as sim:
            sim.run_until(stop)
        assert sim.outcome.status == "completed", sim.outcome
    return time.perf_counter() - began


def swept(project: Path, variants: list[dict], out: Path, workers: int) -> float:
    """Seconds for the same variants as a sweep on a LocalCluster of ``workers`` processes."""
    import hycosim

    settings = [f"{key}=" + ",".join(json.dumps(v[key]) for v in variants) for key in variants[0]]
    began = time.perf_counter()
    table = hycosim.sweep(project, settings, zipped=True, workers=workers, out=out)
    rows = table.to_pylist() if hasattr(table, "to_pylist") else table.to_dict("records")
    assert len(rows) == len(variants) and all(r["outcome"] == "completed" for r in rows), rows[:3]
    return time.perf_counter() - began


def main() -> None:
    """Time the same runs as a plain loop of ``hycosim.open`` and as sweeps on one and two Dask workers;
    print runs a second and the ratios (``--json``: one object)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    rng = random.Random(1)
    variants = [{"dahlquist.k": round(rng.uniform(0.1, 3.0), 6), "vdp.mu": round(rng.uniform(0.5, 2.0), 6)}
                for _ in range(args.runs)]
    with tempfile.TemporaryDirectory(prefix="hycosim-sweep-") as tmp:
        root = Path(tmp)
        project, _ = write_package(root / "pkg", args.steps)
        seconds = {"plain loop of hycosim.open": plain_loop(project, variants, root / "loop"),
                   "sweep, 1 worker": swept(project, variants, root / "one", 1),
                   "sweep, 2 workers": swept(project, variants, root / "two", 2)}
    result = {"runs": args.runs, "steps": args.steps, "seconds": seconds,
              "runs_per_s": {k: args.runs / s for k, s in seconds.items()},
              "two_vs_one": seconds["sweep, 1 worker"] / seconds["sweep, 2 workers"],
              "ms_per_run": {k: 1000 * s / args.runs for k, s in seconds.items()}}
    base = seconds["plain loop of hycosim.open"]
    _table.write(args.table, _table.Table(
        f"{args.runs} runs of {args.steps} steps of the three-FMU system, parameters varied; each sweep starts "
        "its own LocalCluster (counted); × plain loop: time against the loop in the same run:",
        ["way", "runs/s", "ms a run", "× plain loop"],
        [[k, f"{args.runs / s:.1f}", f"{1000 * s / args.runs:.1f}", f"{s / base:.2f}"] for k, s in seconds.items()]))
    if args.json:
        print(json.dumps(result))
        return
    for k, s in seconds.items():
        print(f"{k:28} {args.runs / s:7.1f} runs/s  {1000 * s / args.runs:7.1f} ms a run  {s / base:5.2f}× loop")
    print(f"2 workers against 1: {result['two_vs_one']:.2f}×")


if __name__ == "__main__":
    main()
