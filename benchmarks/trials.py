"""The paper's trials on Dask workers against the same trials one after another: wall time,
trials a minute, and what the trials measured (success, grasp error), in one run.

Each trial is a whole distributed co-simulation paced at real time (server, rod and robot-scene
FMUs, policy, camera: five processes) followed by the EthernetKRL export and the emulated
controller. Serial first, then ``hycosim trials --workers W`` on a LocalCluster of W processes
(its start counted: a user waits for it too). With camera correction the trials' processes share
the machine with the camera's rendering, so on a machine with few cores the figures measured
may differ between the two ways; the table shows both.

    python benchmarks/trials.py [--angles 30 40 50 60] [--trials 3] [--workers 2] [--table FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import _table  # noqa: E402


def measured(angles: list[float], trials: int, out: Path, workers: int | None) -> dict:
    """Seconds for the trials, and their success rate and mean grasp error."""
    from hycosim.scenario.trials import run_trials

    began = time.perf_counter()
    results = run_trials(angles, trials, out, workers=workers)
    seconds = time.perf_counter() - began
    ran = [r for r in results if not r.error]
    assert len(ran) == len(results), [r.error for r in results if r.error][:3]
    errors = [r.grasp_error_mm for r in results if r.success]
    return {"seconds": seconds, "trials": len(results), "success_pct": 100 * len(errors) / len(results),
            "error_mm": sum(errors) / len(errors) if errors else math.nan, "max_error_mm": max(errors, default=math.nan)}


def main() -> None:
    """Run the trials one after another and on Dask workers, and print each way's wall time, rate,
    success and grasp error (``--json``: one object)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--angles", type=float, nargs="+", default=[30, 40, 50, 60])
    ap.add_argument("--trials", type=int, default=3, help="trials per angle")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    from hycosim.scenario.scene_fmus import ensure_scene_fmus
    from hycosim.scenario.trials import FMU_DIR

    ensure_scene_fmus(FMU_DIR)  # built before either way is timed
    with tempfile.TemporaryDirectory(prefix="hycosim-trials-") as tmp:
        ways = {"one after another": measured(args.angles, args.trials, Path(tmp) / "serial", None),
                f"{args.workers} Dask worker{'s' if args.workers > 1 else ''}": measured(args.angles, args.trials, Path(tmp) / "dask", args.workers)}
    base = ways["one after another"]["seconds"]
    n = len(args.angles) * args.trials
    _table.write(args.table, _table.Table(
        f"{n} trials ({', '.join(f'{a:g}°' for a in args.angles)}, {args.trials} each; camera correction, policy, "
        "rod and robot as FMUs); × serial: time against the serial trials in the same run:",
        ["way", "s", "trials/min", "× serial", "success", "error mean / max (mm)"],
        [[k, f"{w['seconds']:.0f}", f"{60 * n / w['seconds']:.1f}", f"{w['seconds'] / base:.2f}",
          f"{w['success_pct']:.0f} %", f"{w['error_mm']:.2f} / {w['max_error_mm']:.2f}"] for k, w in ways.items()]))
    if args.json:
        print(json.dumps(ways))
        return
    for k, w in ways.items():
        print(f"{k:20} {w['seconds']:6.0f} s  {60 * n / w['seconds']:5.1f} trials/min  {w['seconds'] / base:4.2f}× serial"
              f"  success {w['success_pct']:.0f} %  error {w['error_mm']:.2f} / {w['max_error_mm']:.2f} mm")


if __name__ == "__main__":
    main()
