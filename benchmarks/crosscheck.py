"""hycosim against other engines, point by point, on systems of FMUs this benchmark builds.

Systems (benchmarks/_small_fmus.c, FMI 2 co-simulation FMUs, packed as SSP 1.0 by hycosim's
export: parameters bound inline, linear transformations on links):

* **chain**: Dahlquist.x --(2x + 1)--> ft (y = u) --> ft2 (y = u), a direct-feedthrough chain;
* **ball**: a bouncing ball (a state event located inside its steps; e = 0.7 bound by the
  package, 0.8 in its FMU) whose h (--(100 h)-->), bounce count (Integer) and falling flag
  (Boolean) feed a feedthrough of each type (gain = 2 and offset = 10 bound by the package);
* **late**: a constant (y = 3) --(2x + 1)--> ft1 --> ft2, feedthroughs that compute y = u only
  when they leave initialisation mode and in their steps (as pythonfmu FMUs commonly do): the
  start inputs count only if they are set inside initialisation mode, as FMI lays out;
* **vdp** and **bounce**: a Van der Pol oscillator, and the ball, on their own;
* **osp**: an OSP system structure (benchmarks/_small_fmus.osp_structure): initial values of
  Real, Integer and Boolean variables, a multi-rate simulator (the ball, every second step), a
  linear transformation, a sum of one signal and an algebraic loop of two feedthroughs, run
  from the XML by hycosim and by libcosim (``CosimExecution.from_osp_config_file``). libcosim
  initialises the loop by a fixed number of passes over its connections, hycosim to its fixed
  point: the loop's values part by 1/16 at t0, and the difference halves every second step;
* **chain1**, **ball1**, **vdp1**: the chain, the ball and the oscillator of FMI 1.0 builds of
  the same models (benchmarks/_small_fmus1.c), which hycosim runs through fmpy's FMI 1.0
  classes, ECOS through fmi4c and libcosim through FMI Library;
* **override**: the chain with a scenario (hycosim's ``scenario``): ``ft.u`` overridden to 5.0 a
  quarter into the run and released at its half, against libcosim's override manipulator
  (``slave_real_values`` until ``reset_variables``). ECOS has no override: a value set on an
  input a link feeds holds for one step, and is read back before it is set, so it is left out.

Engines: hycosim in processes (``hycosim run``) and in one process (``--in-process``), ECOS
(``ecospy``: an in-process C++ master that reads SSP), libcosim (``libcosimpy``: from the
unpacked package's folder, the step in integer nanoseconds), each in a child process (both
write their log lines to stdout), and for a single FMU ``fmpy.simulate_fmu``. For each
engine and variable: the largest difference from hycosim in processes over every point, and
the time of it. Where the engines record a variable at another moment by design, it is
compared where the values are the same quantity, and the comparison says so:

* ECOS reads a direct-feedthrough output after it set the point's inputs, y(t) = u(t);
  hycosim records what the FMU gave at the end of its step, y(t) = u(t − H): ECOS's value one
  point earlier;
* libcosim records every variable after the step, before it passes the outputs on: an input
  at t is what the links carried at t − H, so hycosim's input is compared with libcosim's one
  point later. libcosimpy reads Booleans only as last values and the execution initialises in
  its first step, so a Boolean's t0 is not compared there.

At t0 every engine initialises the same way (the start inputs set inside the FMUs'
initialisation mode in dependency order, the outputs read there, then every FMU leaves it)
and the same point is compared, but for libcosim's inputs: libcosim records at t0 the input as
set inside initialisation mode, before its links carry what the FMUs gave on leaving it, so
hycosim's input at t0 is compared with libcosim's at the next point, as at every other point.

Goal (issue 58): 0 at every point, t0 included, for every variable of every system, or at most
1e-12 relative where the arithmetic differs: hycosim steps from grid point to grid point, each
step t_(j+1) − t_j with t_j = t0 + j·H (no rounding accumulates in the clock over a long run),
where ECOS passes H itself; the two step sizes differ in their last bit at some points, and so
do the states integrated over them. libcosim keeps time in integer nanoseconds.

    python benchmarks/crosscheck.py [--steps 400] [--h 0.01] [--json]
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
import zipfile
from pathlib import Path

import _table
from _procs import run

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

import _small_fmus  # noqa: E402

# Each engine's child: argv = package, steps, h, then name:type for each variable; prints one
# line "ROWS <json>", a row per point (None where the engine cannot say).
_ECOS = r"""
import json, sys
from ecospy import EcosSimulation
ssp, steps, h, names = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), [a.split(":") for a in sys.argv[5:]]
rows = []
with EcosSimulation(ssp_path=ssp, step_size=h) as sim:
    get = {"Real": sim.get_real, "Integer": sim.get_integer, "Boolean": sim.get_bool}
    sim.init(parameter_set="parameters")  # ECOS binds parameters by set name: hycosim's export names them so
    for k in range(steps + 1):
        if k:
            sim.step(1)
        rows.append([get[t](n.replace(".", "::")) for n, t in names])
print("ROWS " + json.dumps(rows))
"""

_LIBCOSIM = r"""
import json, sys
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
log_output_level(CosimLogLevel.ERROR)
from libcosimpy.CosimEnums import CosimVariableType
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimManipulator import CosimManipulator
folder, steps, h = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
actions, names = json.loads(sys.argv[4]), [a.split(":") for a in sys.argv[5:]]  # actions: [point, variable, value/None]
ex = (CosimExecution.from_osp_config_file(folder) if folder.endswith(".xml")
      else CosimExecution.from_ssp_file(folder, step_size=round(h * 1e9)))
override = CosimManipulator.create_override()
ex.add_manipulator(override)
last, series = CosimObserver.create_last_value(), CosimObserver.create_time_series(steps + 2)
ex.add_observer(last)
ex.add_observer(series)
index = {i.name.decode(): i.index for i in ex.slave_infos()}
refs = {f"{s}.{v.name.decode()}": (index[s], v.reference) for s in index for v in ex.slave_variables(index[s])}
kinds = {"Real": CosimVariableType.REAL, "Integer": CosimVariableType.INTEGER}
for n, t in names:
    if t in kinds:
        series.start_time_series(*refs[n], kinds[t])
read = {"Real": last.last_real_values, "Integer": last.last_integer_values, "Boolean": last.last_boolean_values}
rows = []
for k in range(1, steps + 1):
    for _, var, value in (a for a in actions if a[0] == k - 1):
        slave, ref = refs[var]
        if value is None:
            override.reset_variables(slave, CosimVariableType.REAL, [ref])
        else:
            override.slave_real_values(slave, [ref], [value])
    ex.step(1)
    rows.append([read[t](refs[n][0], [refs[n][1]])[0] for n, t in names])
# t0 from the time series (libcosimpy's sample reader drops what follows a step number 0, so one
# sample past it is asked for)
first = {"Real": series.time_series_real_samples, "Integer": series.time_series_integer_samples}
def at_t0(n, t):
    # A simulator with a step of its own (a multi-rate one) may hold no sample at step 0.
    samples = first[t](*refs[n], 0, 2) if t in first else None
    return samples[2][0] if samples and samples[1] and samples[1][0] == 0 else None
rows.insert(0, [at_t0(n, t) for n, t in names])
print("ROWS " + json.dumps(rows))
"""


def systems(fmus: dict[str, Path], steps: int, h: float, fmus1: dict[str, Path] | None = None) -> dict[str, dict]:
    """Each system's hycosim project; with ``fmus1`` (the FMI 1.0 builds), the chain, the ball
    and the Van der Pol oscillator of those too (``chain1``, ``ball1``, ``vdp1``)."""
    cosim = {"stepSize": h, "stopTime": round(steps * h, 12), "stepTimeout": 30.0}

    def project(name: str, nodes: list[dict], links: list[dict]) -> dict:
        return {"projectName": name, "serverIP": "127.0.0.1:7447", "nodeNum": len(nodes), "nodeLists": nodes,
                "linkNum": len(links), "linkLists": links, "coSimulation": cosim}

    chain = project("chain", [
        {"nodeName": "dahlquist", "UID": 1, "fmu": str(fmus["Dahlquist"]), "input": [], "output": ["x"]},
        {"nodeName": "ft", "UID": 2, "fmu": str(fmus["Feedthrough"]), "input": ["u"], "output": ["y"]},
        {"nodeName": "ft2", "UID": 3, "fmu": str(fmus["Feedthrough"]), "input": ["u"], "output": ["y"]},
    ], [{"from": "dahlquist.x", "to": "ft.u", "factor": 2.0, "offset": 1.0}, {"from": "ft.y", "to": "ft2.u"}])
    ball = {"nodeName": "ball", "UID": 1, "fmu": str(fmus["Ball"]), "parameters": {"e": 0.7}, "input": [],
            "output": ["h", "v", {"name": "bounces", "type": "Integer"}, {"name": "falling", "type": "Boolean"}]}
    out = {
        "chain": chain,
        "ball": project("ball", [
            ball,
            {"nodeName": "types", "UID": 2, "fmu": str(fmus["Types"]), "parameters": {"gain": 2.0, "offset": 10},
             "input": ["ru", {"name": "iu", "type": "Integer"}, {"name": "bu", "type": "Boolean"}],
             "output": ["ry", {"name": "iy", "type": "Integer"}, {"name": "by", "type": "Boolean"}]},
        ], [{"from": "ball.h", "to": "types.ru", "factor": 100.0}, {"from": "ball.bounces", "to": "types.iu"},
            {"from": "ball.falling", "to": "types.bu"}]),
        "vdp": project("vdp", [
            {"nodeName": "vdp", "UID": 1, "fmu": str(fmus["VanDerPol"]), "input": [], "output": ["x0", "x1"]}], []),
        "bounce": project("bounce", [ball], []),
        "late": project("late", [
            {"nodeName": "source", "UID": 1, "fmu": str(fmus["Constant"]), "input": [], "output": ["y"]},
            {"nodeName": "ft1", "UID": 2, "fmu": str(fmus["LateFeedthrough"]), "input": ["u"], "output": ["y"]},
            {"nodeName": "ft2", "UID": 3, "fmu": str(fmus["LateFeedthrough"]), "input": ["u"], "output": ["y"]},
        ], [{"from": "source.y", "to": "ft1.u", "factor": 2.0, "offset": 1.0}, {"from": "ft1.y", "to": "ft2.u"}]),
        "override": dict(chain, projectName="override", scenario=[
            {"t": round(steps // 4 * h, 12), "override": "ft.u", "value": 5.0},
            {"t": round(steps // 2 * h, 12), "release": "ft.u"}]),
    }
    if fmus1 is not None:
        old = systems(fmus1, steps, h)
        out.update({f"{name}1": dict(old[name], projectName=f"{name}1") for name in ("chain", "ball", "vdp")})
    return out


def kinds(doc: dict) -> dict[str, tuple[str, str]]:
    """Each recorded variable's FMI type and role: "feedthrough" (an output that reads an input at
    once, by its FMU's model structure), "input" or "output"."""
    out = {}
    for node in doc["nodeLists"]:
        model = Path(node["fmu"]).stem
        deps = {var: d for var, _, _, _, d in _small_fmus.MODELS[model][1]}
        for role in ("output", "input"):
            for port in node[role]:
                name, type_ = (port, "Real") if isinstance(port, str) else (port["name"], port["type"])
                late = model in _small_fmus.LATE  # its output follows its input a step later, in every engine
                what = "feedthrough" if role == "output" and deps.get(name) and not late else role
                out[f"{node['nodeName']}.{name}"] = (type_, what)
    return out


def hycosim(cfg: Path, runs: Path, in_process: bool, timeout: float) -> dict[str, list[float]]:
    """Every column of one run's values.csv but step and mode, as floats."""
    res = run([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", str(runs), "--no-progress",
               "--in-process" if in_process else "--processes"], timeout, cwd=REPO)
    if res.returncode:
        raise RuntimeError(f"{cfg.name}: {res.stderr[-800:]}")
    run_dir = max(runs.iterdir(), key=lambda p: p.stat().st_mtime)
    with open(run_dir / "values.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return {c: [float(r[c]) for r in rows] for c in rows[0] if c not in ("step", "mode", "stepped")}


def actions(doc: dict, h: float) -> list[list]:
    """A project's scenario as libcosim's override manipulator takes it: [point, variable, value],
    a value of None resetting the variable (a release)."""
    return [[round(a["t"] / h), a.get("override") or a["release"], a.get("value")] for a in doc.get("scenario", [])]


def _engine(script: str, what: str, package: Path, steps: int, h: float, variables: dict[str, tuple[str, str]],
            timeout: float, acts: list) -> dict[str, list[float | None]]:
    res = run([sys.executable, "-c", script, str(package), str(steps), str(h), json.dumps(acts),
               *(f"{n}:{t}" for n, (t, _) in variables.items())], timeout)
    if res.returncode:
        raise RuntimeError(f"{what}: {res.stderr[-800:]}")
    rows = json.loads(next(line for line in res.stdout.splitlines() if line.startswith("ROWS "))[5:])
    return {n: [None if r[i] is None else float(r[i]) for r in rows] for i, n in enumerate(variables)}


def ecos(ssp: Path, steps: int, h: float, variables: dict[str, tuple[str, str]],
         timeout: float, acts: list) -> dict[str, list[float | None]] | None:
    """ECOS's value of each variable at every point, or None where ecospy (or libtbb12) is missing
    or the system has a scenario (ECOS overrides nothing)."""
    if acts:
        return None
    try:
        import ecospy  # noqa: F401
    except (ImportError, OSError):
        return None
    return _engine(_ECOS, "ECOS", ssp, steps, h, variables, timeout, [])


def libcosim(ssp: Path, steps: int, h: float, variables: dict[str, tuple[str, str]],
             timeout: float, acts: list) -> dict[str, list[float | None]] | None:
    """libcosim's value of each variable at every point (from the package unpacked beside it),
    or None where libcosimpy is missing."""
    try:
        import libcosimpy  # noqa: F401
    except (ImportError, OSError):
        return None
    folder = ssp.with_suffix("")
    with zipfile.ZipFile(ssp) as z:
        z.extractall(folder)
    return _engine(_LIBCOSIM, "libcosim", folder, steps, h, variables, timeout, acts)


def libcosim_osp(xml: Path, steps: int, h: float, variables: dict[str, tuple[str, str]],
                 timeout: float) -> dict[str, list[float | None]] | None:
    """libcosim's value of each variable at every point of the OSP system structure ``xml``
    (``CosimExecution.from_osp_config_file``), or None where libcosimpy is missing."""
    try:
        import libcosimpy  # noqa: F401
    except ImportError:
        return None
    return _engine(_LIBCOSIM, "libcosim", xml, steps, h, variables, timeout, [])


def fmpy_single(node: dict, steps: int, h: float, names: list[str]) -> dict[str, list[float]]:
    """``fmpy.simulate_fmu`` of one FMU with the node's parameters, its outputs at every point."""
    import fmpy

    result = fmpy.simulate_fmu(node["fmu"], stop_time=steps * h, step_size=h, output_interval=h,
                               start_values=node.get("parameters", {}),
                               output=[n.split(".", 1)[1] for n in names])
    return {n: [float(v) for v in result[n.split(".", 1)[1]]] for n in names}


# Per engine and role: theirs at point k + shift is ours at point k (the moments they record at).
SHIFTS = {"ECOS": {"feedthrough": -1}, "libcosim": {"input": 1}}
# What an engine is not run on, and why (found by running it there).
LEFT_OUT = {("ball1", "libcosim"): "libcosim leaves an SSP package's parameter bindings off FMI 1.0 FMUs: its "
            "types.ry at t0 is 1 × types.ru (the FMU's own gain), not the package's 2 × types.ru"}
_SAID = {-1: "one point earlier (feedthrough, by design)", 1: "one point later (inputs after the step, by design)",
         0: "same point"}


def compare(ours: dict[str, list[float]], theirs: dict[str, list[float | None]], shifts: dict[str, int],
            roles: dict[str, tuple[str, str]]) -> dict[str, dict]:
    """Per variable: the largest |difference| over the points, its time, its relative size, the
    difference at t0, and how the points were paired."""
    t = ours["t"]
    out = {}
    for name, values in theirs.items():
        mine, d = ours[name], shifts.get(roles[name][1], 0)
        # An input libcosim records later (d = 1) is at t0 the value set inside initialisation
        # mode, before the links carry what the FMUs gave on leaving it: its t0 is compared
        # through the pairing (hycosim's t0 with libcosim's next point), not with itself.
        at_t0 = d <= 0
        pairs = ([(0, 0)] if at_t0 else []) + [(k, k + d) for k in range(len(mine))
                                               if 0 <= k + d < len(values) and (k, k + d) != (0, 0)]
        diffs = [(k, abs(mine[k] - values[j]), abs(values[j])) for k, j in pairs if values[j] is not None]
        worst = max(diffs, key=lambda p: p[1])
        out[name] = {"max_abs_diff": worst[1], "at_t": t[worst[0]], "points": len(diffs), "last_diff": diffs[-1][1],
                     "max_rel_diff": max(a / max(1.0, b) for _, a, b in diffs),
                     "t0_diff": None if values[0] is None or not at_t0 else abs(mine[0] - values[0]),
                     "compared": _SAID[d]}
    return out


def main() -> None:
    """Run every system through hycosim and each reference engine installed (ECOS, libcosim, FMPy; an
    OSP structure through libcosim), compare them point by point and print the differences."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--h", type=float, default=0.01)
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()

    from hycosim.core.config import load_project
    from hycosim.fmi.ssp import write_ssp

    result: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="hycosim-crosscheck-") as tmp:
        root = Path(tmp)
        fmus = _small_fmus.build(root)
        fmus1 = _small_fmus.build1(root / "fmi1")
        for name, doc in systems(fmus, args.steps, args.h, fmus1).items():
            cfg = root / f"{name}.json"
            cfg.write_text(json.dumps(doc))
            roles = kinds(doc)
            ours = hycosim(cfg, root / f"runs-{name}", False, args.timeout)
            engines: dict[str, dict[str, list[float | None]]] = {
                "hycosim in process": hycosim(cfg, root / f"inproc-{name}", True, args.timeout)}
            ssp = write_ssp(load_project(cfg), root / f"{name}.ssp")
            for engine, read in (("ECOS", ecos), ("libcosim", libcosim)):
                if (name, engine) in LEFT_OUT:
                    continue
                theirs = read(ssp, args.steps, args.h, roles, args.timeout, actions(doc, args.h))
                if theirs is not None:
                    engines[engine] = theirs
            if len(doc["nodeLists"]) == 1:
                node = doc["nodeLists"][0]
                engines["fmpy.simulate_fmu"] = fmpy_single(node, args.steps, args.h, list(roles))
            result[name] = {engine: compare(ours, {n: v for n, v in values.items() if n in roles},
                                            SHIFTS.get(engine, {}), roles)
                            for engine, values in engines.items()}
        # An OSP system structure (benchmarks/_small_fmus.osp_structure) in hycosim and libcosim.
        from hycosim.fmi.osp import project_from_osp

        xml = _small_fmus.osp_structure(fmus, root / "osp", args.steps, args.h)
        roles = kinds(project_from_osp(xml, root).project)
        ours = hycosim(xml, root / "runs-osp", False, args.timeout)
        engines = {"hycosim in process": hycosim(xml, root / "inproc-osp", True, args.timeout)}
        theirs = libcosim_osp(xml, args.steps, args.h, roles, args.timeout)
        if theirs is not None:
            engines["libcosim"] = theirs
        result["osp"] = {engine: compare(ours, {n: v for n, v in values.items() if n in roles},
                                         SHIFTS.get(engine, {}), roles) for engine, values in engines.items()}
    _table.write(args.table, _manual_table(args, result))
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f"{'system':7} {'engine':19} {'variable':13} {'at t0':>6} {'max |diff|':>11} {'at t':>7} {'relative':>9}"
          "  compared")
    for system, engines in result.items():
        for engine, variables in engines.items():
            for var, r in variables.items():
                t0 = "-" if r["t0_diff"] is None else f"{r['t0_diff']:.3g}"
                print(f"{system:7} {engine:19} {var:13} {t0:>6} {r['max_abs_diff']:11.3g} {r['at_t']:7.3f} "
                      f"{r['max_rel_diff']:9.2g}  {r['compared']}")


def _manual_table(args: argparse.Namespace, result: dict) -> _table.Table:
    rows = []
    for system, engines in result.items():
        for engine, variables in engines.items():
            t0 = [r["t0_diff"] for r in variables.values() if r["t0_diff"] is not None]
            var, worst = max(variables.items(), key=lambda item: item[1]["max_abs_diff"])
            largest = (f"{worst['max_abs_diff']:.2g} ({var} at t = {worst['at_t']:.2f} s)"
                       if worst["max_abs_diff"] else "0")
            rows.append([system, engine, f"{max(t0):.2g}" if t0 else None, largest,
                         f"{max(r['max_rel_diff'] for r in variables.values()):.2g}"])
    left_out = "".join(f" Not run: {engine} on {system} ({why})." for (system, engine), why in LEFT_OUT.items())
    return _table.Table(f"{args.steps:,} steps of {args.h * 1000:g} ms; per system and engine the largest difference "
                        f"at t0, over every point, and over every point relative to max(1, |value|).{left_out}",
                        ["system", "engine", "at t0", "largest difference", "relative"], rows)


if __name__ == "__main__":
    main()
