"""hycosim against other engines, point by point, on systems of FMUs this benchmark builds.

Systems (benchmarks/_small_fmus.c, FMI 2 co-simulation FMUs, packed as SSP 1.0 by hycosim's
export, linear transformations included):

* **chain**: Dahlquist.x --(2x + 1)--> ft (y = u) --> ft2 (y = u), a direct-feedthrough chain;
* **vdp**: a Van der Pol oscillator on its own.

Engines: hycosim in processes (``hycosim run``) and in one process (``--in-process``), ECOS
(``ecospy``: an in-process C++ master that reads SSP; its log lines go to stdout, so it runs
in a child process), and for the single FMU ``fmpy.simulate_fmu``. For each engine and
variable: the largest difference from hycosim in processes over every point, and the time of
it. Where the schemes differ by design the comparison says so and makes it exactly:

* a direct-feedthrough output (ft.y, ft2.y): ECOS reads it after it set the point's inputs,
  y(t) = u(t); hycosim records what the FMU gave at the end of its step, y(t) = u(t − H). It is
  compared with ECOS's one point earlier (and at t0, where both initialise, at the same point).

Goal (issue 58): 0 at every point, t0 included, for every variable of every system, or at most
1e-12 relative where the arithmetic differs: hycosim steps from grid point to grid point, each
step t_(j+1) − t_j with t_j = t0 + j·H (no rounding accumulates in the clock over a long run),
where ECOS passes H itself; the two step sizes differ in their last bit at some points, and so
do the states integrated over them.

    python benchmarks/crosscheck.py [--steps 400] [--h 0.01] [--json]
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
from pathlib import Path

from _procs import run

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

import _small_fmus  # noqa: E402

FEEDTHROUGH = {"ft.y", "ft2.y"}  # outputs that pass an input through at once

_ECOS = r"""
import json, sys
from ecospy import EcosSimulation
ssp, steps, h, names = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4].split(",")
rows = []
with EcosSimulation(ssp_path=ssp, step_size=h) as sim:
    sim.init()
    for k in range(steps + 1):
        if k:
            sim.step(1)
        rows.append([sim.get_real(n.replace(".", "::")) for n in names])
print("ROWS " + json.dumps(rows))
"""


def systems(fmus: dict[str, Path], steps: int, h: float) -> dict[str, dict]:
    """Each system's hycosim project."""
    cosim = {"stepSize": h, "stopTime": round(steps * h, 12), "stepTimeout": 30.0}

    def project(name: str, nodes: list[dict], links: list[dict]) -> dict:
        return {"projectName": name, "serverIP": "127.0.0.1:7447", "nodeNum": len(nodes), "nodeLists": nodes,
                "linkNum": len(links), "linkLists": links, "coSimulation": cosim}

    return {
        "chain": project("chain", [
            {"nodeName": "dahlquist", "UID": 1, "fmu": str(fmus["Dahlquist"]), "input": [], "output": ["x"]},
            {"nodeName": "ft", "UID": 2, "fmu": str(fmus["Feedthrough"]), "input": ["u"], "output": ["y"]},
            {"nodeName": "ft2", "UID": 3, "fmu": str(fmus["Feedthrough"]), "input": ["u"], "output": ["y"]},
        ], [{"from": "dahlquist.x", "to": "ft.u", "factor": 2.0, "offset": 1.0}, {"from": "ft.y", "to": "ft2.u"}]),
        "vdp": project("vdp", [
            {"nodeName": "vdp", "UID": 1, "fmu": str(fmus["VanDerPol"]), "input": [], "output": ["x0", "x1"]}], []),
    }


def hycosim(cfg: Path, runs: Path, in_process: bool, timeout: float) -> dict[str, list[float]]:
    """Every column of one run's values.csv but step and mode, as floats."""
    res = run([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", str(runs), "--no-progress",
               "--in-process" if in_process else "--processes"], timeout, cwd=REPO)
    if res.returncode:
        raise RuntimeError(f"{cfg.name}: {res.stderr[-800:]}")
    run_dir = max(runs.iterdir(), key=lambda p: p.stat().st_mtime)
    with open(run_dir / "values.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return {c: [float(r[c]) for r in rows] for c in rows[0] if c not in ("step", "mode")}


def ecos(ssp: Path, steps: int, h: float, names: list[str], timeout: float) -> dict[str, list[float]] | None:
    """ECOS's value of each variable at every point, or None where ecospy (or libtbb12) is missing."""
    try:
        import ecospy  # noqa: F401
    except (ImportError, OSError):
        return None
    res = run([sys.executable, "-c", _ECOS, str(ssp), str(steps), str(h), ",".join(names)], timeout)
    if res.returncode:
        raise RuntimeError(f"ECOS: {res.stderr[-800:]}")
    rows = json.loads(next(line for line in res.stdout.splitlines() if line.startswith("ROWS "))[5:])
    return {n: [r[i] for r in rows] for i, n in enumerate(names)}


def fmpy_single(fmu: Path, steps: int, h: float, names: list[str]) -> dict[str, list[float]]:
    """``fmpy.simulate_fmu`` of one FMU, its outputs at every macro-step point."""
    import fmpy

    result = fmpy.simulate_fmu(str(fmu), stop_time=steps * h, step_size=h, output_interval=h,
                               output=[n.split(".", 1)[1] for n in names])
    return {n: [float(v) for v in result[n.split(".", 1)[1]]] for n in names}


def compare(ours: dict[str, list[float]], theirs: dict[str, list[float]], reads_after_inputs: bool) -> dict[str, dict]:
    """Per variable: the largest |difference| over the points, its time, and how it was compared
    (``reads_after_inputs``: an engine that reads outputs after setting the point's inputs)."""
    t = ours["t"]
    out = {}
    for name, values in theirs.items():
        mine = ours[name]
        shifted = reads_after_inputs and name in FEEDTHROUGH
        pairs = [(0, mine[0], values[0])] + [(k, mine[k], values[k - 1 if shifted else k]) for k in range(1, len(mine))]
        worst = max(pairs, key=lambda p: abs(p[1] - p[2]))
        out[name] = {"max_abs_diff": abs(worst[1] - worst[2]), "at_t": t[worst[0]], "points": len(pairs),
                     "max_rel_diff": max(abs(a - b) / max(1.0, abs(b)) for _, a, b in pairs),
                     "t0_diff": abs(pairs[0][1] - pairs[0][2]),
                     "compared": "one point earlier (feedthrough, by design)" if shifted else "same point"}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--h", type=float, default=0.01)
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    from hycosim.core.config import load_project
    from hycosim.fmu_bridge.ssp import write_ssp

    result: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="hycosim-crosscheck-") as tmp:
        root = Path(tmp)
        fmus = _small_fmus.build(root)
        for name, doc in systems(fmus, args.steps, args.h).items():
            cfg = root / f"{name}.json"
            cfg.write_text(json.dumps(doc))
            ours = hycosim(cfg, root / f"runs-{name}", False, args.timeout)
            names = [c for c in ours if c != "t"]
            engines = {"hycosim in process": hycosim(cfg, root / f"inproc-{name}", True, args.timeout)}
            theirs = ecos(write_ssp(load_project(cfg), root / f"{name}.ssp"), args.steps, args.h, names, args.timeout)
            if theirs is not None:
                engines["ECOS"] = theirs
            if len(doc["nodeLists"]) == 1:
                node = doc["nodeLists"][0]
                engines["fmpy.simulate_fmu"] = fmpy_single(Path(node["fmu"]), args.steps, args.h,
                                                           [n for n in names if n.startswith(node["nodeName"] + ".")])
            result[name] = {engine: compare(ours, {n: v for n, v in values.items() if n in names}, engine == "ECOS")
                            for engine, values in engines.items()}
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f"{'system':7} {'engine':20} {'variable':12} {'at t0':>6} {'max |diff|':>11} {'at t':>7} {'relative':>9}  compared")
    for system, engines in result.items():
        for engine, variables in engines.items():
            for var, r in variables.items():
                print(f"{system:7} {engine:20} {var:12} {r['t0_diff']:6.3g} {r['max_abs_diff']:11.3g} {r['at_t']:7.3f} "
                      f"{r['max_rel_diff']:9.2g}  {r['compared']}")


if __name__ == "__main__":
    main()
