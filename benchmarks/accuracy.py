"""Accuracy and cost of the master algorithms, against the monolithic solution.

The reference problems, each split across FMUs the benchmark builds (benchmarks/_mass_fmu.c,
a native FMI 2 FMU that can interpolate its inputs: one FMU, an instance per mass, each in its
own node process; every mass integrates its own ODE finely, so that the error is the
coupling's):

* the two-mass oscillator coupled through a spring (force–displacement coupling: mass 1 gives
  its displacement, mass 2 holds the coupling spring and gives back the force it puts on mass 1;
  m = 1 kg, k1 = k2 = 10 N/m, kc = 100 N/m, x1(0) = 0.1 m);
* a chain of three masses (the same springs, the middle mass holding both coupling springs and
  taking both neighbours' displacements: two coupled loops).

Each coupling runs at each macro step H through ``hycosim run``; the reference is the exact
solution of the whole linear system (its matrix exponential, by eigendecomposition). Reported
per run: the global error (max |x − x_ref| of the first and second mass over the run), the
energy drift |E(T) − E(0)| / E(0), macro steps, takes (every iteration counted) and wall time.

Iterative coupling (Jacobi, each step taken again until its inputs stop changing) beside
Jacobi and Gauss-Seidel: with the inputs held at the step's end value (``iterative``), and
following polynomials of degree 1 to 3 over the step (``interpolated-n``: FMI input
derivatives). Beside them the whole system as one model integrated by RK4 at H (the
monolithic solution's order of accuracy), and each scheme's observed order between
consecutive H. The error-controlled step on a case with one sharp transient (the
damped two-mass system at rest, mass 1 struck by a 20 ms pulse): fixed H = 1 ms against the
controlled step at several tolerances, with the exact solution around the pulse as reference.

Multi-rate: a 1 kHz source feeding a 100 Hz node feeding a 1 Hz node, run with those rates
(releases batched, as by default, and once with one release per base point) and once all at
1 kHz: the frames exchanged (releases sent, frames the server took in), whether the fast
node's values are the same, and whether batching left every recorded value as it was.

    python benchmarks/accuracy.py [--stop 2] [--h 0.01 0.005 0.002] [--problems two three] [--mr-stop 2]
                                  [--transient-stop 5] [--tolerances 1e-4 3e-5 1e-5] [--plot PNG] [--json]
                                  [--in-process]

With ``--in-process`` every run is ``hycosim run --in-process`` (the master and every node in
one process): the same values, takes and frames, in a fraction of the time; its wall times
are in-process ones.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import _table
from _procs import free_port, run

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))
M1 = M2 = M3 = 1.0
K1 = K2 = K3 = 10.0
KC = 100.0
X10 = 0.1


def build_mass_fmu(dir_: Path) -> Path:
    """The mass FMU (benchmarks/_mass_fmu.c, compiled): its state saved and restored, its inputs interpolated."""
    import _mass_fmu

    return _mass_fmu.build(dir_ / "fmu")


def _run(cfg: Path, runs: Path, in_process: bool = False, timeout: float = 600) -> tuple[Path, float]:
    began = time.perf_counter()
    res = run([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", str(runs), "--no-progress",
               *(["--in-process"] if in_process else [])], timeout, cwd=REPO)
    wall = time.perf_counter() - began
    if res.returncode:
        raise SystemExit(f"{cfg}: run failed ({res.returncode}): {res.stderr.strip()[-800:]}")
    return max(runs.iterdir(), key=lambda p: p.stat().st_mtime), wall


def _columns(run_dir: Path) -> dict[str, np.ndarray]:
    with open(run_dir / "values.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return {key: np.array([float(r[key]) for r in rows]) for key in rows[0] if key not in ("mode", "stepped")}


# The master algorithms compared: each a coupling and what else goes in coSimulation. Gauss-Seidel:
# the masses that take a force go first (on the force at the step's start), then the one holding
# the springs, on their new displacements.
SCHEMES = {"jacobi": {"coupling": "jacobi"}, "gauss-seidel": {"coupling": "gauss-seidel"},
           "iterative": {"coupling": "jacobi", "iterate": {"tolerance": 1e-9, "maxIterations": 30}},
           **{f"interpolated-{n}": {"coupling": "jacobi", "iterate": {"tolerance": 1e-10, "maxIterations": 30,
                                                                      "interpolate": n}} for n in (1, 2, 3)}}
ORDER = {"two": ["m1", "m2"], "three": ["m1", "m3", "m2"]}


def _mass(name: str, uid: int, fmu: Path, inputs: list[str], outputs: list[str], **parameters) -> dict:
    return {"nodeName": name, "UID": uid, "fmu": str(fmu), "input": inputs, "output": ["x", "v", *outputs],
            "parameters": parameters}


def oscillator(dir_: Path, fmu: Path, scheme: str, h: float, stop: float, problem: str = "two", **extra) -> Path:
    """A reference problem (``two`` masses or ``three`` in a chain) under a scheme of SCHEMES
    (``extra``: more parameters for a node by its name, and ``cosim``)."""
    if problem == "two":
        nodes = [_mass("m1", 1, fmu, ["F"], [], m=M1, k=K1, x=X10),
                 _mass("m2", 2, fmu, ["xl"], ["Fl"], m=M2, k=K2, kl=KC, xl=X10)]
        links = [{"from": "m1.x", "to": "m2.xl"}, {"from": "m2.Fl", "to": "m1.F"}]
    else:
        nodes = [_mass("m1", 1, fmu, ["F"], [], m=M1, k=K1, x=X10),
                 _mass("m2", 2, fmu, ["xl", "xr"], ["Fl", "Fr"], m=M2, k=K2, kl=KC, kr=KC, xl=X10),
                 _mass("m3", 3, fmu, ["F"], [], m=M3, k=K3)]
        links = [{"from": "m1.x", "to": "m2.xl"}, {"from": "m3.x", "to": "m2.xr"},
                 {"from": "m2.Fl", "to": "m1.F"}, {"from": "m2.Fr", "to": "m3.F"}]
    for node in nodes:
        node["parameters"].update(extra.get(node["nodeName"], {}))
    cosim = {"stepSize": h, "stopTime": stop, **SCHEMES.get(scheme, {}), **extra.get("cosim", {})}
    if scheme == "gauss-seidel":
        cosim["order"] = ORDER[problem]
    doc = {"projectName": "osc", "serverIP": f"127.0.0.1:{free_port()}", "nodeNum": len(nodes), "nodeLists": nodes,
           "linkNum": len(links), "linkLists": links, "coSimulation": cosim}
    path = dir_ / f"osc-{problem}-{scheme}-{h:g}-{len(list(dir_.glob('osc-*')))}.json"
    path.write_text(json.dumps(doc))
    return path


def _system(problem: str = "two", c: float = 0.0) -> np.ndarray:
    """The monolithic system y' = A·y, y = [x1, v1, x2, v2(, x3, v3)]."""
    if problem == "two":
        masses, stiffness = [M1, M2], np.array([[K1 + KC, -KC], [-KC, K2 + KC]])
    else:
        masses = [M1, M2, M3]
        stiffness = np.array([[K1 + KC, -KC, 0], [-KC, K2 + 2 * KC, -KC], [0, -KC, K3 + KC]])
    n = len(masses)
    a = np.zeros((2 * n, 2 * n))
    for i in range(n):
        a[2 * i, 2 * i + 1] = 1.0
        a[2 * i + 1, 2 * i + 1] = -c / masses[i]
        for j in range(n):
            a[2 * i + 1, 2 * j] = -stiffness[i, j] / masses[i]
    return a


def _free(a: np.ndarray, y0: np.ndarray, t: np.ndarray) -> np.ndarray:
    """exp(a·t)·y0 for each t, exactly, by eigendecomposition."""
    w, v = np.linalg.eig(a)
    c = np.linalg.solve(v, y0.astype(complex))
    return np.real((v[None, :, :] * (c * np.exp(np.outer(t, w)))[:, None, :]).sum(axis=2))


def reference(t: np.ndarray, problem: str = "two") -> np.ndarray:
    """The monolithic solution [x1, v1, x2, v2(, x3, v3)] at times t, exactly (the system is linear)."""
    a = _system(problem)
    y0 = np.zeros(len(a))
    y0[0] = X10
    return _free(a, y0, t)


def pulse(s: float, at: float, width: float, peak: float) -> float:
    """The half-sine force pulse of _mass_fmu.Mass: ``peak`` newtons at its middle, nothing outside."""
    return peak * math.sin(math.pi * (s - at) / width) if at <= s <= at + width else 0.0


def pulse_reference(t: np.ndarray, c: float, at: float, width: float, peak: float) -> np.ndarray:
    """The monolithic solution of the damped two-mass system at rest until mass 1 is struck by the
    pulse: exact before and after it, RK4 at 1 µs through it."""
    a = _system("two", c)
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


def monolithic_rk4(h: float, stop: float, problem: str = "two") -> dict:
    """The whole system as one model, integrated by RK4 at the macro step h (one RK4 step a macro
    step, as a monolithic tool would): the order of accuracy iterative coupling is set against."""
    a = _system(problem)
    y = np.zeros(len(a))
    y[0] = X10
    n = int(round(stop / h))
    t = h * np.arange(n + 1)
    path = [y]
    for _ in range(n):
        k1 = a @ y
        k2 = a @ (y + h / 2 * k1)
        k3 = a @ (y + h / 2 * k2)
        k4 = a @ (y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        path.append(y)
    path, ref = np.array(path), reference(t, problem)
    return {"problem": problem, "H": h, "macro_steps": n, "error_x1": float(np.max(np.abs(path[:, 0] - ref[:, 0]))),
            "error_x2": float(np.max(np.abs(path[:, 2] - ref[:, 2])))}


def observed_orders(rows: list[dict], key: str = "coupling") -> dict[str, dict[str, list[float]]]:
    """Per problem and coupling, log(e1 / e2) / log(H1 / H2) of x1's error between consecutive H."""
    out: dict[str, dict[str, list[float]]] = {}
    for r in rows:
        out.setdefault(r["problem"], {}).setdefault(r.get(key, "monolithic RK4"), [])
    for problem, by in out.items():
        for scheme in by:
            mine = sorted((r for r in rows if r["problem"] == problem and r.get(key, "monolithic RK4") == scheme),
                          key=lambda r: -r["H"])
            by[scheme] = [round(math.log(a["error_x1"] / b["error_x1"]) / math.log(a["H"] / b["H"]), 2)
                          for a, b in zip(mine, mine[1:])]
    return out


def energy(c: dict[str, np.ndarray], problem: str = "two") -> np.ndarray:
    """The system's energy at every recorded point (kinetic, the wall springs, the coupling springs)."""
    x = [c[f"m{i}.x"] for i in (1, 2, 3) if f"m{i}.x" in c]
    v = [c[f"m{i}.v"] for i in (1, 2, 3) if f"m{i}.v" in c]
    m, k = [M1, M2, M3], [K1, K2, K3]
    e = sum(0.5 * m[i] * v[i] ** 2 + 0.5 * k[i] * x[i] ** 2 for i in range(len(x)))
    return e + sum(0.5 * KC * (x[i + 1] - x[i]) ** 2 for i in range(len(x) - 1))


def _takes(run_dir: Path) -> int:
    """Every take of every step (an iterated or rejected step counts each time)."""
    with open(run_dir / "timing.csv", newline="") as f:
        rows = list(csv.DictReader(f))[1:]
    return sum(int(r.get("takes") or 1) for r in rows)


def accuracy(dir_: Path, fmu: Path, steps: list[float], stop: float, problems: list[str],
             in_process: bool = False) -> list[dict]:
    """Each problem at each macro step size under each coupling scheme: error against the analytic
    solution, energy drift, takes and wall time, one row a run."""
    rows = []
    for problem in problems:
        for h in steps:
            for scheme in SCHEMES:
                run_dir, wall = _run(oscillator(dir_, fmu, scheme, h, stop, problem),
                                     dir_ / f"runs-{problem}-{scheme}-{h:g}", in_process)
                c = _columns(run_dir)
                ref = reference(c["t"], problem)
                e = energy(c, problem)
                rows.append({"problem": problem, "coupling": scheme, "H": h, "macro_steps": len(c["t"]) - 1,
                             "takes": _takes(run_dir), "wall_s": round(wall, 2),
                             "error_x1": float(np.max(np.abs(c["m1.x"] - ref[:, 0]))),
                             "error_x2": float(np.max(np.abs(c["m2.x"] - ref[:, 2]))),
                             "energy_drift": float(abs(e[-1] - e[0]) / e[0])})
    return rows


# The sharp-transient case: the damped system at rest, mass 1 struck at 1 s by a 20 ms pulse.
DAMPING, PULSE = 20.0, {"pulse_at": 1.0, "pulse_width": 0.02, "pulse": 50.0}


def transient(dir_: Path, fmu: Path, stop: float, tolerances: list[float], fixed: float = 0.001,
              in_process: bool = False) -> list[dict]:
    """Jacobi at a fixed H = ``fixed`` against the error-controlled step at each tolerance."""
    at_rest = {"m1": {"x": 0.0, "c": DAMPING, **PULSE}, "m2": {"xl": 0.0, "c": DAMPING}}
    cases = [("fixed", fixed, {})] + [
        ("controlled", tol, {"stepControl": {"tolerance": tol, "minStep": 1e-4, "maxStep": 0.2}}) for tol in tolerances]
    rows = []
    for kind, value, cosim in cases:
        cfg = oscillator(dir_, fmu, "jacobi", fixed if kind == "fixed" else 0.01, stop, **at_rest, cosim=cosim)
        run_dir, wall = _run(cfg, dir_ / f"runs-transient-{kind}-{value:g}", in_process)
        c = _columns(run_dir)
        ref = pulse_reference(c["t"], DAMPING, PULSE["pulse_at"], PULSE["pulse_width"], PULSE["pulse"])
        meta = json.loads((run_dir / "meta.json").read_text())
        rows.append({"step": f"H = {value:g} s" if kind == "fixed" else f"tolerance {value:g}",
                     "macro_steps": len(c["t"]) - 1, "takes": _takes(run_dir),
                     "rejected": (meta.get("step_sizes") or {}).get("rejected", 0), "wall_s": round(wall, 2),
                     "error_x1": float(np.max(np.abs(c["m1.x"] - ref[:, 0]))),
                     "error_x2": float(np.max(np.abs(c["m2.x"] - ref[:, 2])))})
    return rows


def rates_chain(dir_: Path, stop: float, rates: bool, batch: bool = True) -> Path:
    """A project of three nodes in a chain (a fast ramp, two gains) in ``dir_``, multi-rate where
    ``rates``, batched where ``batch``; its path."""
    nodes = [{"nodeName": "fast", "UID": 1, "model": "ramp", "output": ["y", "v"]},
             {"nodeName": "mid", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
             {"nodeName": "slow", "UID": 3, "model": "gain", "input": ["u"], "output": ["y"]}]
    if rates:
        nodes[1]["stepSize"], nodes[2]["stepSize"] = 0.01, 1.0
    doc = {"projectName": "rates", "serverIP": f"127.0.0.1:{free_port()}", "nodeNum": 3, "nodeLists": nodes,
           "linkNum": 2, "linkLists": [{"from": "fast.y", "to": "mid.u"}, {"from": "mid.y", "to": "slow.u"}],
           "coSimulation": {"stepSize": 0.001, "stopTime": stop, "batchReleases": batch}}
    path = dir_ / f"chain-{'multi' if rates else 'single'}-{batch}.json"
    path.write_text(json.dumps(doc))
    return path


def multirate(dir_: Path, stop: float, in_process: bool = False) -> dict:
    """The chain single-rate, multi-rate and multi-rate unbatched: points, releases and frames of each,
    their ratios, and whether the fast node's values and the batching left the results unchanged."""
    out = {}
    fast = {}
    values = {}
    for key, rates, batch in (("single_rate", False, True), ("multi_rate", True, True),
                              ("multi_rate_unbatched", True, False)):
        run_dir, wall = _run(rates_chain(dir_, stop, rates, batch), dir_ / f"runs-chain-{key}", in_process)
        meta = json.loads((run_dir / "meta.json").read_text())
        c = _columns(run_dir)
        # Releases (STEP or STEPS; the START and STOP are the same in both) and the nodes' frames taken in.
        releases, received = meta["messages"]["releases"], meta["messages"]["received"]
        values[key] = (run_dir / "values.csv").read_bytes()
        out[key] = {"points": len(c["t"]), "releases": releases, "frames_in": received,
                    "messages": releases + received, "wall_s": round(wall, 2), "coupling": meta["coupling"]}
        fast[key] = c["fast.y"]
    out["message_ratio"] = out["multi_rate"]["messages"] / out["single_rate"]["messages"]
    out["unbatched_message_ratio"] = out["multi_rate_unbatched"]["messages"] / out["single_rate"]["messages"]
    out["fast_node_identical"] = bool(np.array_equal(fast["multi_rate"], fast["single_rate"]))
    out["batching_changes_nothing"] = values["multi_rate"] == values["multi_rate_unbatched"]
    return out


def plot(rows: list[dict], sharp: list[dict], out: Path, monolithic: list[dict] | None = None) -> Path:
    """Global error and energy drift against steps taken (every take counted): a colour per
    coupling, solid for two masses and dashed for three, the monolithic RK4 at H in black;
    the sharp transient's fixed and controlled steps beside them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import NullFormatter

    fig, axes = plt.subplots(1, 3 if sharp else 2, figsize=(15 if sharp else 10, 5.2))
    colours = {scheme: f"C{i}" for i, scheme in enumerate(SCHEMES)}
    styles = {"two": "-o", "three": "--s"}
    for problem in dict.fromkeys(r["problem"] for r in rows):
        for scheme in SCHEMES:
            mine = sorted((r for r in rows if r["problem"] == problem and r["coupling"] == scheme),
                          key=lambda r: r["takes"])
            for ax, key in ((axes[0], "error_x1"), (axes[1], "energy_drift")):
                ax.loglog([r["takes"] for r in mine], [r[key] for r in mine], styles[problem], color=colours[scheme],
                          markersize=4)
    for problem in dict.fromkeys(r["problem"] for r in monolithic or []):
        mine = sorted((r for r in monolithic if r["problem"] == problem), key=lambda r: r["macro_steps"])
        axes[0].loglog([r["macro_steps"] for r in mine], [r["error_x1"] for r in mine], styles[problem], color="k",
                       markersize=4)
    axes[0].set(xlabel="steps taken (every take counted)", ylabel="global error in x1 (m)")
    axes[1].set(xlabel="steps taken (every take counted)", ylabel="energy drift |E(T) − E(0)| / E(0)")
    if sharp:
        for r in sharp:
            axes[2].loglog(r["takes"], r["error_x1"], "o", label=r["step"])
        axes[2].set(xlabel="steps taken (every take counted)", ylabel="global error in x1 (m)", title="sharp transient, Jacobi")
        axes[2].legend(fontsize=7)
    for ax in axes:
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes[:2]:
        ax.yaxis.set_minor_formatter(NullFormatter())
    handles = [Line2D([], [], color=colours[s], label=s) for s in SCHEMES]
    handles += [Line2D([], [], color="k", label="monolithic RK4 at H")]
    handles += [Line2D([], [], color="grey", linestyle=styles[p][:-1], marker=styles[p][-1], label=f"{p} masses")
                for p in styles]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def main() -> None:
    """Measure and print the figures (``--json``: one object); the manual's table with ``--table``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stop", type=float, default=2.0)
    ap.add_argument("--h", type=float, nargs="+", default=[0.01, 0.005, 0.002])
    ap.add_argument("--problems", nargs="+", choices=["two", "three"], default=["two", "three"])
    ap.add_argument("--mr-stop", type=float, default=2.0)
    ap.add_argument("--transient-stop", type=float, default=5.0, help="0: leave the sharp-transient case out")
    ap.add_argument("--tolerances", type=float, nargs="+", default=[1e-4, 3e-5, 1e-5])
    ap.add_argument("--fixed-h", type=float, default=0.001, help="the fixed step the controlled one is set against")
    ap.add_argument("--plot", type=Path, help="write the error-against-cost figure here (PNG)")
    ap.add_argument("--in-process", action="store_true",
                    help="every run in one process (hycosim run --in-process): the same values, no start-up of "
                         "processes; the wall times are then in-process ones")
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        dir_ = Path(tmp)
        fmu = build_mass_fmu(dir_)
        rows = accuracy(dir_, fmu, args.h, args.stop, args.problems, args.in_process)
        rates = multirate(dir_, args.mr_stop, args.in_process)
        sharp = (transient(dir_, fmu, args.transient_stop, args.tolerances, args.fixed_h, args.in_process)
                 if args.transient_stop > 0 else [])
    by = {(r["problem"], r["coupling"], r["H"]): r for r in rows}
    ratios = {problem: {f"{h:g}": by[(problem, "gauss-seidel", h)]["error_x1"] / by[(problem, "jacobi", h)]["error_x1"]
                        for h in args.h} for problem in args.problems}
    monolithic = [monolithic_rk4(h, args.stop, problem) for problem in args.problems for h in args.h]
    orders = observed_orders(rows + monolithic)
    result = {"oscillator": rows, "gs_over_jacobi_error": ratios, "monolithic_rk4": monolithic, "orders": orders,
              "multirate": rates, "transient": sharp}
    if args.plot:
        result["plot"] = str(plot(rows, sharp, args.plot, monolithic))
    _table.write(args.table, *_manual_tables(args, rows, monolithic, orders, rates, sharp))
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f"{'masses':<8}{'coupling':<17}{'H (s)':>8}{'steps':>8}{'takes':>8}{'wall (s)':>10}{'err x1 (m)':>13}"
          f"{'err x2 (m)':>13}{'energy drift':>14}")
    for r in rows:
        print(f"{r['problem']:<8}{r['coupling']:<17}{r['H']:>8g}{r['macro_steps']:>8}{r['takes']:>8}"
              f"{r['wall_s']:>10.2f}{r['error_x1']:>13.3e}{r['error_x2']:>13.3e}{r['energy_drift']:>14.3e}")
    for r in monolithic:
        print(f"{r['problem']:<8}{'monolithic RK4':<17}{r['H']:>8g}{r['macro_steps']:>8}{'':>8}{'':>10}"
              f"{r['error_x1']:>13.3e}{r['error_x2']:>13.3e}")
    for problem, by_h in ratios.items():
        print(f"Gauss-Seidel / Jacobi global error at the same H, {problem} masses: "
              + ", ".join(f"H={h}: {v:.2f}" for h, v in by_h.items()))
    for problem, by_scheme in orders.items():
        print(f"observed order in H (x1's error between consecutive H), {problem} masses: "
              + "; ".join(f"{scheme} {', '.join(f'{o:.2f}' for o in got)}" for scheme, got in by_scheme.items()))
    s, m = rates["single_rate"], rates["multi_rate"]
    print(f"multi-rate 1 kHz / 100 Hz / 1 Hz against all at 1 kHz: {m['messages']:,} vs {s['messages']:,} frames "
          f"(ratio {rates['message_ratio']:.3f}; {rates['unbatched_message_ratio']:.2f} with one release per base "
          f"point); fast node's values identical: {rates['fast_node_identical']}; values.csv the same batched and "
          f"not: {rates['batching_changes_nothing']}")
    if sharp:
        print(f"sharp transient (pulse at {PULSE['pulse_at']:g} s, {args.transient_stop:g} s run), Jacobi:")
        print(f"{'step':<18}{'steps':>8}{'takes':>8}{'rejected':>10}{'wall (s)':>10}{'err x1 (m)':>13}{'err x2 (m)':>13}")
        for r in sharp:
            print(f"{r['step']:<18}{r['macro_steps']:>8}{r['takes']:>8}{r['rejected']:>10}{r['wall_s']:>10.2f}"
                  f"{r['error_x1']:>13.3e}{r['error_x2']:>13.3e}")
    if args.plot:
        print(f"figure: {args.plot}")


def _manual_tables(args: argparse.Namespace, rows: list[dict], monolithic: list[dict], orders: dict,
                   rates: dict, sharp: list[dict]) -> list[_table.Table]:
    by = {(r["problem"], r["coupling"], r["H"]): r for r in rows}
    rk4 = {(r["problem"], r["H"]): r for r in monolithic}

    def err(problem: str, scheme: str, h: float, takes: bool = False) -> str:
        r = by[(problem, scheme, h)]
        return f"{r['error_x1']:.2e} m" + (f" ({r['takes']:,})" if takes else "")

    order = "; ".join(f"{problem} masses: " + ", ".join(f"{scheme} {min(got):.2f}–{max(got):.2f}"
                                                         for scheme, got in by_scheme.items() if got)
                      for problem, by_scheme in orders.items())
    tables = [
        _table.Table(f"Largest error in x1 against the exact solution, {args.stop:g} s simulated; in brackets the "
                     "takes of every step:",
                     ["masses", "H", "Jacobi", "Gauss-Seidel", "iterative, inputs held", "degree 1", "degree 2",
                      "degree 3", "RK4 on the whole system"],
                     [[problem, f"{h * 1000:g} ms", err(problem, "jacobi", h), err(problem, "gauss-seidel", h),
                       err(problem, "iterative", h, True), err(problem, "interpolated-1", h),
                       err(problem, "interpolated-2", h), err(problem, "interpolated-3", h, True),
                       f"{rk4[(problem, h)]['error_x1']:.2e} m"] for problem in args.problems for h in args.h],
                     after=f"Observed order in H: {order}." if order else ""),
        _table.Table(f"Multi-rate, a 1 kHz source → 100 Hz → 1 Hz chain over {args.mr_stop:g} s:",
                     ["frames multi-rate", "frames all at 1 kHz", "ratio", "the fast node's values identical",
                      "`values.csv` the same unbatched"],
                     [[f"{rates['multi_rate']['messages']:,}", f"{rates['single_rate']['messages']:,}",
                       f"{rates['message_ratio']:.3f}", rates["fast_node_identical"], rates["batching_changes_nothing"]]])]
    if sharp:
        tables.append(_table.Table(
            f"Step control: the damped oscillator struck at {PULSE['pulse_at']:g} s by a {PULSE['pulse']:g} N "
            f"half-sine pulse of {PULSE['pulse_width'] * 1000:g} ms, {args.transient_stop:g} s, Jacobi:",
            ["step", "macro steps", "takes", "rejected", "max error x1", "max error x2"],
            [[r["step"], f"{r['macro_steps']:,}", f"{r['takes']:,}", r["rejected"], f"{r['error_x1']:.2e} m",
              f"{r['error_x2']:.2e} m"] for r in sharp]))
    return tables


if __name__ == "__main__":
    main()
