"""Accuracy and cost of the master algorithms, against the monolithic solution.

The two-mass oscillator coupled through a spring (force–displacement coupling: mass 1 gives
its displacement, mass 2 gives back the spring's force; m = 1 kg, k1 = k2 = 10 N/m,
kc = 100 N/m, x1(0) = 0.1 m), split in two nodes (benchmarks/_oscillator.py, each node
integrating its own ODE finely, so that the error is the coupling's). Each coupling runs at
each macro step H through ``hycosim run``; the reference is the exact solution of the whole
linear system (its matrix exponential, by eigendecomposition). Reported per run: the global
error (max |x1 − x1_ref| and |x2 − x2_ref| over the run), the energy drift |E(T) − E(0)| / E(0),
macro steps and wall time.

Multi-rate: a 1 kHz source feeding a 100 Hz node feeding a 1 Hz node, run once with those
rates and once all at 1 kHz: the frames exchanged (releases sent, frames the server took in)
and whether the fast node's values are the same.

    python benchmarks/accuracy.py [--stop 2] [--h 0.01 0.005 0.002] [--mr-stop 2] [--json]
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


def oscillator(dir_: Path, coupling: str, h: float, stop: float) -> Path:
    model = str(HERE / "_oscillator.py")
    doc = {"projectName": "osc", "serverIP": f"127.0.0.1:{free_port()}", "nodeNum": 2,
           "nodeLists": [
               {"nodeName": "m1", "UID": 1, "model": f"{model}:Mass1", "input": ["F"], "output": ["x", "v"],
                "parameters": {"m": M1, "k": K1, "x0": X10}},
               {"nodeName": "m2", "UID": 2, "model": f"{model}:Mass2", "input": ["x1"], "output": ["x", "v", "F"],
                "parameters": {"m": M2, "k": K2, "kc": KC, "x1_0": X10}}],
           "linkNum": 2, "linkLists": [{"from": "m1.x", "to": "m2.x1"}, {"from": "m2.F", "to": "m1.F"}],
           "coSimulation": {"stepSize": h, "stopTime": stop, "coupling": coupling}}
    if coupling == "gauss-seidel":  # the two read each other: mass 1 first, on the force at the step's start
        doc["coSimulation"]["order"] = ["m1", "m2"]
    path = dir_ / f"osc-{coupling}-{h:g}.json"
    path.write_text(json.dumps(doc))
    return path


def reference(t: np.ndarray) -> np.ndarray:
    """The monolithic solution [x1, v1, x2, v2] at times t, exactly (the system is linear)."""
    a = np.array([[0, 1, 0, 0],
                  [-(K1 + KC) / M1, 0, KC / M1, 0],
                  [0, 0, 0, 1],
                  [KC / M2, 0, -(K2 + KC) / M2, 0]], dtype=float)
    w, v = np.linalg.eig(a)
    c = np.linalg.solve(v, np.array([X10, 0.0, 0.0, 0.0]))
    return np.real((v[None, :, :] * (c * np.exp(np.outer(t, w)))[:, None, :]).sum(axis=2))


def energy(x1, v1, x2, v2) -> np.ndarray:
    return 0.5 * (M1 * v1 ** 2 + M2 * v2 ** 2 + K1 * x1 ** 2 + K2 * x2 ** 2 + KC * (x2 - x1) ** 2)


def accuracy(dir_: Path, steps: list[float], stop: float) -> list[dict]:
    rows = []
    for h in steps:
        for coupling in ("jacobi", "gauss-seidel"):
            run_dir, wall = _run(oscillator(dir_, coupling, h, stop), dir_ / f"runs-{coupling}-{h:g}")
            c = _columns(run_dir)
            ref = reference(c["t"])
            e = energy(c["m1.x"], c["m1.v"], c["m2.x"], c["m2.v"])
            rows.append({"coupling": coupling, "H": h, "macro_steps": len(c["t"]) - 1, "wall_s": round(wall, 2),
                         "error_x1": float(np.max(np.abs(c["m1.x"] - ref[:, 0]))),
                         "error_x2": float(np.max(np.abs(c["m2.x"] - ref[:, 2]))),
                         "energy_drift": float(abs(e[-1] - e[0]) / e[0])})
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
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        dir_ = Path(tmp)
        rows = accuracy(dir_, args.h, args.stop)
        rates = multirate(dir_, args.mr_stop)
    by = {(r["coupling"], r["H"]): r for r in rows}
    ratios = {f"{h:g}": by[("gauss-seidel", h)]["error_x1"] / by[("jacobi", h)]["error_x1"] for h in args.h}
    result = {"oscillator": rows, "gs_over_jacobi_error": ratios, "multirate": rates}
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f"{'coupling':<14}{'H (s)':>8}{'steps':>8}{'wall (s)':>10}{'err x1 (m)':>13}{'err x2 (m)':>13}"
          f"{'energy drift':>14}")
    for r in rows:
        print(f"{r['coupling']:<14}{r['H']:>8g}{r['macro_steps']:>8}{r['wall_s']:>10.2f}{r['error_x1']:>13.3e}"
              f"{r['error_x2']:>13.3e}{r['energy_drift']:>14.3e}")
    print("Gauss-Seidel / Jacobi global error at the same H: "
          + ", ".join(f"H={h}: {v:.2f}" for h, v in ratios.items()))
    s, m = rates["single_rate"], rates["multi_rate"]
    print(f"multi-rate 1 kHz / 100 Hz / 1 Hz against all at 1 kHz: {m['messages']:,} vs {s['messages']:,} frames "
          f"(ratio {rates['message_ratio']:.2f}); fast node's values identical: {rates['fast_node_identical']}")


if __name__ == "__main__":
    main()
