"""One host, one process: ``hycosim run --in-process`` against the distributed run and against ECOS.

Two systems, each run by every contender in the same session, rounds interleaved, medians of
steps/s (``meta.json``'s, or the engine's own clock around its stepping):

* **the barrier ring** of benchmarks/barrier.py (N Python nodes, y = 0.5·u + 1): hycosim
  in processes over Zenoh on loopback (``hycosim run``) against in process (``--in-process``);
* **three FMI 2 co-simulation FMUs** (benchmarks/_small_fmus.c: a Dahlquist, a Feedthrough fed
  through a linear transformation, a Van der Pol) as one SSP package: ECOS (``ecospy``, an
  in-process C++ master that reads SSP, recording every variable with its CSV writer as hycosim
  records every port), a bare Jacobi loop over fmpy's ``FMU2Slave`` (the floor of a Python
  master), hycosim in process and in processes, and the same run driven from Python
  (``hycosim.open(...).run_until(stop)``: its master waits at each point for the caller's word).

It also checks that the in-process run's ``values.csv`` is byte-identical to the distributed
run's, for the ring and for the package (and the Python-driven run's to both).

Goals (issue 57): in process ≥ 10× the distributed run on the ring at N = 2 and 4; ≥ 0.25× ECOS
on the package.

    python benchmarks/inprocess.py [--n 2 4] [--ring-steps 20000] [--fmu-steps 40000] [--repeat 3] [--json]
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
from _procs import run

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

import _small_fmus  # noqa: E402
from barrier import ring_config  # noqa: E402


def hycosim_run(cfg: Path, runs: Path, in_process: bool, timeout: float) -> tuple[float, bytes]:
    """steps/s and values.csv of one ``hycosim run``."""
    res = run([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", str(runs), "--no-progress",
               "--in-process" if in_process else "--processes"], timeout, cwd=REPO)
    if res.returncode:
        raise RuntimeError(f"{cfg.name} ({'in process' if in_process else 'processes'}): {res.stderr[-800:]}")
    run_dir = max(runs.iterdir(), key=lambda p: p.stat().st_mtime)
    return float(json.loads((run_dir / "meta.json").read_text())["steps_per_s"]), (run_dir / "values.csv").read_bytes()


_OPEN = r"""
import json, sys
import hycosim
with hycosim.open(sys.argv[1], runs_dir=sys.argv[2]) as sim:
    sim.run_until(float(sys.argv[3]))
print("RUN " + json.dumps({"status": sim.outcome.status, "run_dir": str(sim.run_dir)}))
"""


def hycosim_open(package: Path, runs: Path, stop: float, timeout: float) -> tuple[float, bytes]:
    """steps/s and values.csv of the run ``hycosim.open`` drives to its stop time (in a child process)."""
    res = run([sys.executable, "-c", _OPEN, str(package), str(runs), repr(stop)], timeout, cwd=REPO)
    if res.returncode:
        raise RuntimeError(f"hycosim.open: {res.stderr[-800:]}")
    said = json.loads(next(line for line in res.stdout.splitlines() if line.startswith("RUN "))[4:])
    if said["status"] != "completed":
        raise RuntimeError(f"hycosim.open: the run ended {said['status']}")
    run_dir = Path(said["run_dir"])
    return float(json.loads((run_dir / "meta.json").read_text())["steps_per_s"]), (run_dir / "values.csv").read_bytes()


_ECOS = r"""
import sys, time
from ecospy import EcosSimulation
ssp, steps, h, csv = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
with EcosSimulation(ssp_path=ssp, step_size=h) as sim:
    sim.add_csv_writer(csv)
    sim.init()
    began = time.perf_counter()
    sim.step(steps)
    print("steps/s", steps / (time.perf_counter() - began), flush=True)
    sim.terminate()
"""

_FMPY_LOOP = r"""
import sys, time
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
paths, steps, h = sys.argv[1:4], int(sys.argv[4]), float(sys.argv[5])
slaves, refs = [], []
for i, path in enumerate(paths):
    md = read_model_description(path)
    s = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName=f"i{i}")
    s.instantiate(); s.setupExperiment(startTime=0.0); s.enterInitializationMode(); s.exitInitializationMode()
    slaves.append(s)
    refs.append({v.name: v.valueReference for v in md.modelVariables})
dq, ft, vdp = slaves
x, u = refs[0]["x"], refs[1]["u"]
y, x0, x1 = refs[1]["y"], refs[2]["x0"], refs[2]["x1"]
began = time.perf_counter()
t = 0.0
for k in range(steps):
    # Jacobi: read every output at t, route (with the link's transformation), step all.
    xv = dq.getReal([x])[0]
    ft.getReal([y]); vdp.getReal([x0, x1])
    ft.setReal([u], [2.0 * xv + 1.0])
    for s in slaves:
        s.doStep(currentCommunicationPoint=t, communicationStepSize=h)
    t = (k + 1) * h
print(steps / (time.perf_counter() - began))
"""


def ecos(ssp: Path, steps: int, h: float, out: Path, timeout: float) -> float | None:
    """ECOS's steps/s, or None where ecospy (or Debian's libtbb12) is not installed."""
    try:
        import ecospy  # noqa: F401
    except (ImportError, OSError):
        return None
    res = run([sys.executable, "-c", _ECOS, str(ssp), str(steps), str(h), str(out)], timeout)
    if res.returncode:
        raise RuntimeError(f"ECOS: {res.stderr[-800:]}")
    # ECOS writes its own log lines to stdout too
    return float(next(line for line in res.stdout.splitlines() if line.startswith("steps/s")).split()[1])


def fmpy_loop(fmus: dict[str, Path], steps: int, h: float, timeout: float) -> float:
    """The steps/s of a plain FMPy loop over the three FMUs (the floor of a Python master in one
    process)."""
    res = run([sys.executable, "-c", _FMPY_LOOP, *(str(fmus[n]) for n in ("Dahlquist", "Feedthrough", "VanDerPol")),
               str(steps), str(h)], timeout)
    if res.returncode:
        raise RuntimeError(f"fmpy loop: {res.stderr[-800:]}")
    return float(res.stdout.split()[-1])


def main() -> None:
    """Measure in-process runs against distributed runs and ECOS in interleaved rounds and print the
    medians (``--json``: one object)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[2, 4], help="ring sizes")
    ap.add_argument("--ring-steps", type=int, default=20_000)
    ap.add_argument("--fmu-steps", type=int, default=40_000)
    ap.add_argument("--repeat", type=int, default=3, help="rounds, interleaved")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds one run may take")
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    h = 0.01
    rates: dict[str, list[float]] = {}
    identical: dict[str, bool] = {}
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        rings = {n: ring_config(n, args.ring_steps, root / f"ring{n}.json") for n in args.n}
        _, package = _small_fmus.write_package(root / "fmus", args.fmu_steps)
        fmus = {name: root / "fmus" / f"{name}.fmu" for name in _small_fmus.MODELS}
        for r in range(args.repeat):
            for n, cfg in rings.items():
                for mode in (False, True):
                    rate, values = hycosim_run(cfg, root / f"runs-{n}-{mode}-{r}", mode, args.timeout)
                    rates.setdefault(f"ring N={n} {'in process' if mode else 'processes'}", []).append(rate)
                    if r == 0:
                        identical.setdefault(f"ring N={n}", []).append(values)
            for mode in (False, True):
                rate, values = hycosim_run(package, root / f"runs-fmu-{mode}-{r}", mode, args.timeout)
                rates.setdefault(f"3 FMUs hycosim {'in process' if mode else 'processes'}", []).append(rate)
                if r == 0:
                    identical.setdefault("3 FMUs", []).append(values)
            rate, values = hycosim_open(package, root / f"runs-open-{r}", round(args.fmu_steps * h, 12), args.timeout)
            rates.setdefault("3 FMUs hycosim.open", []).append(rate)
            if r == 0:
                identical.setdefault("3 FMUs", []).append(values)
            rates.setdefault("3 FMUs fmpy loop", []).append(fmpy_loop(fmus, args.fmu_steps, h, args.timeout))
            theirs = ecos(package, args.fmu_steps, h, root / f"ecos-{r}.csv", args.timeout)
            if theirs is not None:
                rates.setdefault("3 FMUs ECOS", []).append(theirs)
    median = {k: statistics.median(v) for k, v in rates.items()}
    ratios = {f"ring N={n} in process / processes": median[f"ring N={n} in process"] / median[f"ring N={n} processes"]
              for n in args.n}
    if "3 FMUs ECOS" in median:
        for who in ("hycosim in process", "hycosim processes", "fmpy loop"):
            ratios[f"3 FMUs {who} / ECOS"] = median[f"3 FMUs {who}"] / median["3 FMUs ECOS"]
    ratios["3 FMUs hycosim.open / in process"] = median["3 FMUs hycosim.open"] / median["3 FMUs hycosim in process"]
    same = {k: all(x == v[0] for x in v[1:]) for k, v in identical.items()}
    result = {"date": time.strftime("%Y-%m-%d"), "ring_steps": args.ring_steps, "fmu_steps": args.fmu_steps,
              "repeat": args.repeat, "median_steps_per_s": median, "ratios": ratios,
              "values_identical": same, "ecos": "3 FMUs ECOS" in median}
    rows = [[f"ring N={n}", _table.rate(median[f"ring N={n} processes"]), _table.rate(median[f"ring N={n} in process"]),
             None, None, None, f"{ratios[f'ring N={n} in process / processes']:.1f}× in processes", same[f"ring N={n}"]]
            for n in args.n]
    ecos_ratio = ratios.get("3 FMUs hycosim in process / ECOS")
    rows.append(["3 FMUs", _table.rate(median["3 FMUs hycosim processes"]), _table.rate(median["3 FMUs hycosim in process"]),
                 _table.rate(median["3 FMUs hycosim.open"]),
                 _table.rate(median["3 FMUs fmpy loop"]), _table.rate(median.get("3 FMUs ECOS")),
                 f"{ecos_ratio:.2f}× ECOS" if ecos_ratio else None, same["3 FMUs"]])
    _table.write(args.table, _table.Table(
        f"Steps/s, medians of {args.repeat} interleaved rounds (the ring {args.ring_steps:,} steps, the three FMUs "
        f"{args.fmu_steps:,}); the ratio is of the run in process:",
        ["system", "in processes", "in process", "`hycosim.open`", "fmpy loop", "ECOS", "ratio",
         "`values.csv` identical"], rows))
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f"{time.strftime('%Y-%m-%d')}: medians of {args.repeat} interleaved rounds, steps/s")
    for k, v in median.items():
        print(f"  {k:32s} {v:10,.0f}")
    for k, v in ratios.items():
        print(f"  {k:40s} {v:6.2f}x")
    if not result["ecos"]:
        print("  ECOS: not installed (pip install 'hycosim[bench]'; it needs Debian's libtbb12)")
    for k, v in same.items():
        print(f"  values.csv in process == in processes ({k}): {v}")


if __name__ == "__main__":
    main()
