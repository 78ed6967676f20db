"""Accuracy and cost of the master algorithms, against the monolithic solution.

The two-mass oscillator coupled through a spring (force–displacement coupling: mass 1 gives
its displacement, mass 2 gives back the spring's force; m = 1 kg, k1 = k2 = 10 N/m,
kc = 100 N/m, x1(0) = 0.1 m), split in two nodes (benchmarks/_oscillator.py, each node
integrating its own ODE finely, so that the error is the coupling's). Each coupling runs at
each macro step H through ``hycosim run``; the reference is the exact solution of the whole
linear system (its matrix exponential, by eigendecomposition). Reported per run: the global
error (max |x1 − x1_ref| and |x2 − x2_ref| over the run), the energy drift |E(T) − E(0)| / E(0),
macro steps and wall time.

Iterative coupling (Jacobi, each step taken again until its inputs stop changing) beside
Jacobi and Gauss-Seidel. The error-controlled step on a case with one sharp transient (the
damped system at rest, mass 1 struck by a 20 ms pulse): fixed H = 1 ms against the controlled
step at several tolerances, with the exact solution around the pulse as reference.

Multi-rate: a 1 kHz source feeding a 100 Hz node feeding a 1 Hz node, run once with those
rates and once all at 1 kHz: the frames exchanged (releases sent, frames the server took in)
and whether the fast node's values are the same.

    python benchmarks/accuracy.py [--stop 2] [--h 0.01 0.005 0.002] [--mr-stop 2] [--transient-stop 5]
                                  [--tolerances 0.01 0.005 0.002] [--json]
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _procs import free_port, run

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
M1 = M2 = 1.0
K1 = K2 = 10.0
KC = 100.0
X10 = 0.1


def _run(cfg: Path, runs: Path, timeout: float = 600) -> tuple[Path, float]:
    began = time.perf_counter()
    res = run([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", str(runs), "--no-progress"],
              timeout, cwd=REPO)
    wall = time.perf_counter() - began
    if res.returncode:
        raise SystemExit(f"{cfg}: run failed ({res.returncode}): {res.stderr.strip()[-800:]}")
    return max(runs.iterdir(), key=lambda p: p.stat().st_mtime), wall


def _columns(run_dir: Path) -> dict[str, np.ndarray]:
    with open(run_dir / "values.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return {key: np.array([float(r[key]) for r in rows]) for key in rows[0] if key not in ("mode", "stepped")}


# The master algorithms compared: each a coupling and what else goes in coSimulation.
SCHEMES = {"jacobi": {"coupling": "jacobi"}, "gauss-seidel": {"coupling": "gauss-seidel", "order": ["m1", "m2"]},
           "iterative": {"coupling": "jacobi", "iterate": {"tolerance": 1e-9, "maxIterations": 30}}}


def oscillator(dir_: Path, scheme: str, h: float, stop: float, **extra) -> Path:
    """The two-mass oscillator under a scheme of SCHEMES (``extra``: more node parameters, for both)."""
    model = str(HERE / "_oscillator.py")
    doc = {"projectName": "osc", "serverIP": f"127.0.0.1:{free_port()}", "nodeNum": 2,
           "nodeLists": [
               {"nodeName": "m1", "UID": 1, "model": f"{model}:Mass1", "input": ["F"], "output": ["x", "v"],
                "parameters": {"m": M1, "k": K1, "x0": X10, **extra.get("m1", {})}},
               {"nodeName": "m2", "UID": 2, "model": f"{model}:Mass2", "input": ["x1"], "output": ["x", "v", "F"],
                "parameters": {"m": M2, "k": K2, "kc": KC, "x1_0": X10, **extra.get("m2", {})}}],
           "linkNum": 2, "linkLists": [{"from": "m1.x", "to": "m2.x1"}, {"from": "m2.F", "to": "m1.F"}],
           # Gauss-Seidel: the two read each other, so mass 1 goes first, on the force at the step's start.
           "coSimulation": {"stepSize": h, "stopTime": stop, **SCHEMES.get(scheme, {}), **extra.get("cosim", {})}}
    path = dir_ / f"osc-{scheme}-{h:g}-{len(list(dir_.glob('osc-*')))}.json"
    path.write_text(json.dumps(doc))
    return path


def _system(c: float = 0.0) -> np.ndarray:
    return np.array([[0, 1, 0, 0],
                     [-(K1 + KC) / M1, -c / M1, KC / M1, 0],
                     [0, 0, 0, 1],
                     [KC / M2, 0, -(K2 + KC) / M2, -c / M2]], dtype=float)


def _free(a: np.ndarray, y0: np.ndarray, t: np.ndarray) -> np.ndarray:
    """exp(a·t)·y0 for each t, exactly, by eigendecomposition."""
    w, v = np.linalg.eig(a)
    c = np.linalg.solve(v, y0.astype(complex))
    return np.real((v[None, :, :] * (c * np.exp(np.outer(t, w)))[:, None, :]).sum(axis=2))


def reference(t: np.ndarray) -> np.ndarray:
    """The monolithic solution [x1, v1, x2, v2] at times t, exactly (the system is linear)."""
    return _free(_system(), np.array([X10, 0.0, 0.0, 0.0]), t)


def pulse_reference(t: np.ndarray, c: float, at: float, width: float, peak: float) -> np.ndarray:
    """The monolithic solution of the damped system at rest until mass 1 is struck by the pulse:
    exact before and after it, RK4 at 1 µs through it."""
    from _oscillator import pulse

    a = _system(c)
    n = int(round(width / 1e-6))
    dt = width / n
    grid, y = [np.zeros(4)], np.zeros(4)
    f = lambda s, y: a @ y + np.array([0.0, pulse(s, at, width, peak) / M1, 0.0, 0.0])  # noqa: E731
    for i in range(n):
        s = at + i * dt
        k1 = f(s, y)
        k2 = f(s + dt / 2, y + dt / 2 * k1)
        k3 = f(s + dt / 2, y + dt / 2 * k2)
        k4 = f(s + dt, y + dt * k3)
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        grid.append(y)
    grid = np.array(grid)
    out = np.zeros((len(t), 4))
    inside = (t >= at) & (t <= at + width)
    for j in range(4):
        out[inside, j] = np.interp(t[inside], at + dt * np.arange(n + 1), grid[:, j])
    after = t > at + width
    out[after] = _free(a, grid[-1], t[after] - at - width)
    return out


def energy(x1, v1, x2, v2) -> np.ndarray:
    return 0.5 * (M1 * v1 ** 2 + M2 * v2 ** 2 + K1 * x1 ** 2 + K2 * x2 ** 2 + KC * (x2 - x1) ** 2)


def _takes(run_dir: Path) -> int:
    """Every take of every step (an iterated or rejected step counts each time)."""
    with open(run_dir / "timing.csv", newline="") as f:
        rows = list(csv.DictReader(f))[1:]
    return sum(int(r.get("takes") or 1) for r in rows)


def accuracy(dir_: Path, steps: list[float], stop: float) -> list[dict]:
    rows = []
    for h in steps:
        for scheme in SCHEMES:
            run_dir, wall = _run(oscillator(dir_, scheme, h, stop), dir_ / f"runs-{scheme}-{h:g}")
            c = _columns(run_dir)
            ref = reference(c["t"])
            e = energy(c["m1.x"], c["m1.v"], c["m2.x"], c["m2.v"])
            rows.append({"coupling": scheme, "H": h, "macro_steps": len(c["t"]) - 1, "takes": _takes(run_dir),
                         "wall_s": round(wall, 2),
                         "error_x1": float(np.max(np.abs(c["m1.x"] - ref[:, 0]))),
                         "error_x2": float(np.max(np.abs(c["m2.x"] - ref[:, 2]))),
                         "energy_drift": float(abs(e[-1] - e[0]) / e[0])})
    return rows


# The sharp-transient case: the damped system at rest, mass 1 struck at 1 s by a 20 ms pulse.
DAMPING, PULSE = 20.0, {"pulse_at": 1.0, "pulse_width": 0.02, "pulse": 50.0}


def transient(dir_: Path, stop: float, tolerances: list[float], fixed: float = 0.001) -> list[dict]:
    """Jacobi at a fixed H = ``fixed`` against the error-controlled step at each tolerance."""
    at_rest = {"m1": {"x0": 0.0, "c": DAMPING, **PULSE}, "m2": {"x1_0": 0.0, "c": DAMPING}}
    cases = [("fixed", fixed, {})] + [
        ("controlled", tol, {"stepControl": {"tolerance": tol, "minStep": 1e-4, "maxStep": 0.2}}) for tol in tolerances]
    rows = []
    for kind, value, cosim in cases:
        cfg = oscillator(dir_, "jacobi", fixed if kind == "fixed" else 0.01, stop, **at_rest, cosim=cosim)
        run_dir, wall = _run(cfg, dir_ / f"runs-transient-{kind}-{value:g}")
        c = _columns(run_dir)
        ref = pulse_reference(c["t"], DAMPING, PULSE["pulse_at"], PULSE["pulse_width"], PULSE["pulse"])
        meta = json.loads((run_dir / "meta.json").read_text())
        rows.append({"step": f"H = {value:g} s" if kind == "fixed" else f"tolerance {value:g}",
                     "macro_steps": len(c["t"]) - 1, "takes": _takes(run_dir),
                     "rejected": (meta.get("step_sizes") or {}).get("rejected", 0), "wall_s": round(wall, 2),
                     "error_x1": float(np.max(np.abs(c["m1.x"] - ref[:, 0]))),
                     "error_x2": float(np.max(np.abs(c["m2.x"] - ref[:, 2])))})
    return rows


def chain(dir_: Path, stop: float, rates: bool) -> Path:
    nodes = [{"nodeName": "fast", "UID": 1, "model": "ramp", "output": ["y", "v"]},
             {"nodeName": "mid", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
             {"nodeName": "slow", "UID": 3, "model": "gain", "input": ["u"], "output": ["y"]}]
    if rates:
        nodes[1]["stepSize"], nodes[2]["stepSize"] = 0.01, 1.0
    doc = {"projectName": "rates", "serverIP": f"127.0.0.1:{free_port()}", "nodeNum": 3, "nodeLists": nodes,
           "linkNum": 2, "linkLists": [{"from": "fast.y", "to": "mid.u"}, {"from": "mid.y", "to": "slow.u"}],
           "coSimulation": {"stepSize": 0.001, "stopTime": stop}}
    path = dir_ / f"chain-{'multi' if rates else 'single'}.json"
    path.write_text(json.dumps(doc))
    return path


def multirate(dir_: Path, stop: float) -> dict:
    out = {}
    fast = {}
    for rates in (False, True):
        run_dir, wall = _run(chain(dir_, stop, rates), dir_ / f"runs-chain-{rates}")
        meta = json.loads((run_dir / "meta.json").read_text())
        c = _columns(run_dir)
        points = len(c["t"])
        releases = points - 1  # one release per base point before stopTime (the START aside)
        received = sum(meta["server_waits"].values())
        key = "multi_rate" if rates else "single_rate"
        out[key] = {"releases": releases, "frames_in": received, "messages": releases + received,
                    "wall_s": round(wall, 2)}
        fast[key] = c["fast.y"]
    out["message_ratio"] = out["multi_rate"]["messages"] / out["single_rate"]["messages"]
    out["fast_node_identical"] = bool(np.array_equal(fast["multi_rate"], fast["single_rate"]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stop", type=float, default=2.0)
    ap.add_argument("--h", type=float, nargs="+", default=[0.01, 0.005, 0.002])
    ap.add_argument("--mr-stop", type=float, default=2.0)
    ap.add_argument("--transient-stop", type=float, default=5.0, help="0: leave the sharp-transient case out")
    ap.add_argument("--tolerances", type=float, nargs="+", default=[1e-2, 5e-3, 2e-3])
    ap.add_argument("--fixed-h", type=float, default=0.001, help="the fixed step the controlled one is set against")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        dir_ = Path(tmp)
        rows = accuracy(dir_, args.h, args.stop)
        rates = multirate(dir_, args.mr_stop)
        sharp = transient(dir_, args.transient_stop, args.tolerances, args.fixed_h) if args.transient_stop > 0 else []
    by = {(r["coupling"], r["H"]): r for r in rows}
    ratios = {f"{h:g}": by[("gauss-seidel", h)]["error_x1"] / by[("jacobi", h)]["error_x1"] for h in args.h}
    result = {"oscillator": rows, "gs_over_jacobi_error": ratios, "multirate": rates, "transient": sharp}
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f"{'coupling':<14}{'H (s)':>8}{'steps':>8}{'takes':>8}{'wall (s)':>10}{'err x1 (m)':>13}"
          f"{'err x2 (m)':>13}{'energy drift':>14}")
    for r in rows:
        print(f"{r['coupling']:<14}{r['H']:>8g}{r['macro_steps']:>8}{r['takes']:>8}{r['wall_s']:>10.2f}"
              f"{r['error_x1']:>13.3e}{r['error_x2']:>13.3e}{r['energy_drift']:>14.3e}")
    print("Gauss-Seidel / Jacobi global error at the same H: "
          + ", ".join(f"H={h}: {v:.2f}" for h, v in ratios.items()))
    s, m = rates["single_rate"], rates["multi_rate"]
    print(f"multi-rate 1 kHz / 100 Hz / 1 Hz against all at 1 kHz: {m['messages']:,} vs {s['messages']:,} frames "
          f"(ratio {rates['message_ratio']:.2f}); fast node's values identical: {rates['fast_node_identical']}")
    if sharp:
        print(f"sharp transient (pulse at {PULSE['pulse_at']:g} s, {args.transient_stop:g} s run), Jacobi:")
        print(f"{'step':<18}{'steps':>8}{'takes':>8}{'rejected':>10}{'wall (s)':>10}{'err x1 (m)':>13}{'err x2 (m)':>13}")
        for r in sharp:
            print(f"{r['step']:<18}{r['macro_steps']:>8}{r['takes']:>8}{r['rejected']:>10}{r['wall_s']:>10.2f}"
                  f"{r['error_x1']:>13.3e}{r['error_x2']:>13.3e}")


if __name__ == "__main__":
    main()
