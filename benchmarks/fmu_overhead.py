"""FMU overheads per macro step, measured in one run.

1. A model as an FMU node (pythonfmu, through fmpy) against the same model as a plain
   Python node: both in-process (the node's step call alone) and in a whole
   co-simulation over Zenoh (one node, so the barrier's round trip is the rest).
2. A generated native bridge FMU driven by a C-only importer through the TCP gateway,
   against a Zenoh Python node and the raw Zenoh round trip (benchmarks/_zenoh_floor.py).
3. A Model Exchange FMU (the tests' bouncing ball, C, FMI 2.0) integrated by its node with
   CVode, macro step by macro step, against ``fmpy.simulate_fmu`` of it with the macro step as
   output interval, both in this process: the node's overhead per macro step.

    python benchmarks/fmu_overhead.py [--steps 3000] [--repeat 3] [--timeout 300] [--json]

One run scatters by tens of per cent on a small machine, so every measurement runs
``--repeat`` times, the rounds interleaved, and the figures are the medians.

Each co-simulation has ``--timeout`` seconds; past it, its processes are killed (all of
them: benchmarks/_procs.py) and the benchmark stops with a message naming the measurement.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

from hycosim.bridge.bridge_fmu import build_bridge_fmu  # noqa: E402
from hycosim.core.config import load_project, parse_project  # noqa: E402
from hycosim.bridge.model_fmu import build_model_fmu  # noqa: E402

import _table  # noqa: E402
from _procs import free_port, run, start, stop_all  # noqa: E402

KEYS = ["python_node_step_us", "fmu_node_step_us", "python_node_cosim_steps_per_s", "fmu_node_cosim_steps_per_s",
        "bridge_fmu_cosim_steps_per_s", "zenoh_floor_steps_per_s", "me_node_step_us", "fmpy_me_step_us"]
BRIDGE_NODE = {"nodeName": "tool", "UID": 9, "input": ["u"], "output": ["y"]}


def _project(tmp: Path, node: dict, steps: int) -> Path:
    port = free_port()
    doc = {"projectName": "bench", "serverIP": f"127.0.0.1:{port}", "gatewayIP": f"127.0.0.1:{free_port()}",
           "nodeNum": 1, "nodeLists": [node], "linkNum": 1,
           "linkLists": [{"from": f"{node['nodeName']}.y", "to": f"{node['nodeName']}.u"}],
           "coSimulation": {"stepSize": 1.0, "stopTime": float(steps), "stepTimeout": 30.0}}
    path = tmp / f"{node['nodeName']}.json"
    path.write_text(json.dumps(doc))
    return path


def cosim(cfg: Path, tmp: Path, timeout: float) -> float:
    """The steps/s of the co-simulation in ``cfg`` (from its meta.json)."""
    res = run([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", str(tmp / "runs"), "--no-progress"],
              timeout, cwd=REPO)
    if res.returncode:
        raise RuntimeError(res.stderr)
    metas = sorted((tmp / "runs").glob("bench-*/meta.json"), key=lambda p: p.stat().st_mtime)
    return float(json.loads(metas[-1].read_text())["steps_per_s"])


def in_process(fmu: Path, steps: int) -> tuple[float, float]:
    """Seconds a macro step takes the gain as a Python node and as the FMU ``fmu``, each stepped in this
    process."""
    from hycosim.node.fmu_node import FmuNode
    from hycosim.node.interface import NodeContext
    from hycosim.node.reference.gain import Gain

    doc = {"nodeNum": 2, "nodeLists": [
        {"nodeName": "f", "UID": 1, "fmu": str(fmu), "input": ["u"], "output": ["y"]},
        {"nodeName": "p", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]}]}
    project = parse_project(doc).project
    results = []
    for spec, impl in ((project.node("p"), Gain()), (project.node("f"), FmuNode(project.node("f"), fmu))):
        impl.setup(NodeContext(spec.nodeName, spec.UID, list(spec.input), list(spec.output),
                               {"k": 0.5, "b": 1.0}, 1.0, 0.0))
        y = impl.outputs()["y"]
        t0 = time.perf_counter()
        for k in range(steps):
            impl.step(float(k), 1.0, {"u": y})
            y = impl.outputs()["y"]
        results.append((time.perf_counter() - t0) / steps)
        impl.teardown()
    return results[0], results[1]


def model_exchange(fmu: Path, steps: int) -> tuple[float, float]:
    """Seconds per macro step (H = 10 ms) of the ME ball: its node stepped in this process, and
    fmpy.simulate_fmu of it with that output interval."""
    import logging

    import structlog
    from fmpy import simulate_fmu

    from hycosim.node.fmu_node import FmuNode
    from hycosim.node.interface import NodeContext

    h, stop = 0.01, steps * 0.01
    structlog.configure(wrapper_class=structlog.make_filtering_bound_logger(logging.WARNING))  # its events: not here
    spec = parse_project({"nodeNum": 1, "nodeLists": [{"nodeName": "ball", "UID": 1, "fmu": str(fmu),
                                                       "output": ["h", "v"]}]}).project.node("ball")
    node = FmuNode(spec, fmu)
    node.setup(NodeContext("ball", 1, [], list(spec.output), {}, h, 0.0, stop_time=stop))
    t0 = time.perf_counter()
    for k in range(steps):
        node.step(k * h, h, {})
        node.outputs()
    ours = (time.perf_counter() - t0) / steps
    node.teardown()
    t0 = time.perf_counter()
    simulate_fmu(str(fmu), fmi_type="ModelExchange", stop_time=stop, output_interval=h, output=["h", "v"],
                 record_events=False)
    return ours, (time.perf_counter() - t0) / steps


@dataclass
class Bridge:
    """A generated bridge FMU, extracted, and the C-only importer that drives it."""

    exe: Path
    binary: Path
    guid: str
    resources: str


def build_bridge(tmp: Path, steps: int) -> Bridge:
    """A bridge FMU of the benchmark's node, built and extracted, and the C importer that drives it."""
    cfg = _project(tmp, BRIDGE_NODE, steps)
    built = build_bridge_fmu(load_project(cfg), "tool", tmp / "fmus")
    with zipfile.ZipFile(built.path) as zf:
        zf.extractall(tmp / "bridge")
    exe = tmp / "importer"
    headers = Path(__import__("fmpy").__file__).parent / "c-code"
    subprocess.run(["gcc", "-O2", f"-I{headers}", "-o", str(exe), str(REPO / "tests" / "c" / "importer.c"), "-ldl"],
                   check=True)
    return Bridge(exe, tmp / "bridge" / "binaries" / "linux64" / "hycosim_tool.so", built.guid,
                  (tmp / "bridge").as_uri())


def bridge(tmp: Path, built: Bridge, steps: int, timeout: float, run_dir: Path) -> float:
    """The steps/s of a run whose node is the bridge FMU, driven by the C importer, into ``run_dir``."""
    cfg = _project(tmp, BRIDGE_NODE, steps)  # fresh ports for every run
    gateway = json.loads(cfg.read_text())["gatewayIP"]
    server = start([sys.executable, "-m", "hycosim", "server", str(cfg), "--run-dir", str(run_dir)],
                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=REPO)
    deadline = time.monotonic() + timeout  # one limit for the importer and the server together
    try:
        imp = run([str(built.exe), str(built.binary), built.guid, built.resources, gateway, str(steps), "1.0"],
                  timeout)
        _, server_err = server.communicate(timeout=max(0.0, deadline - time.monotonic()))
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"timed out after {timeout:g} s (--timeout): the bridge FMU's server") from None
    finally:
        stop_all(server)
    if imp.returncode or server.returncode:
        raise RuntimeError(imp.stderr + server_err)
    return float(json.loads((run_dir / "meta.json").read_text())["steps_per_s"])


def main() -> None:
    """Measure the FMU overheads in interleaved rounds and print them (``--json``: one object)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--repeat", type=int, default=3, help="interleaved rounds; the figures are their medians")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per co-simulation before it is killed")
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    try:
        figures = measure(args.steps, args.timeout, args.repeat)
    except RuntimeError as exc:
        raise SystemExit(f"fmu_overhead: {exc}") from None
    _table.write(args.table, _manual_table(args, figures))
    if args.json:
        print(json.dumps(figures))
        return
    print(f"medians of {args.repeat} interleaved runs, {args.steps} macro steps each")
    report(figures)


def measure(steps: int, timeout: float, repeat: int) -> dict[str, float]:
    """Median of ``repeat`` interleaved rounds of every measurement."""
    runs: dict[str, list[float]] = {key: [] for key in KEYS}
    with tempfile.TemporaryDirectory() as tmpname:
        tmp = Path(tmpname)
        fmu = build_model_fmu(REPO / "tests" / "models" / "gain_model.py", tmp)
        built = build_bridge(tmp, steps)
        from tests.me_fmus import build_me_fmus

        ball = build_me_fmus(tmp)["me"]
        python_node = {"nodeName": "py", "UID": 1, "model": "gain", "parameters": {"k": 0.5, "b": 1.0},
                       "input": ["u"], "output": ["y"]}
        fmu_node = {"nodeName": "fmu", "UID": 1, "fmu": str(fmu), "input": ["u"], "output": ["y"]}
        for r in range(repeat):
            py_step, fmu_step = in_process(fmu, steps)
            runs["python_node_step_us"].append(py_step * 1e6)
            runs["fmu_node_step_us"].append(fmu_step * 1e6)
            for key, node, what in (("python_node_cosim_steps_per_s", python_node, "the Python node's"),
                                    ("fmu_node_cosim_steps_per_s", fmu_node, "the FMU node's")):
                try:
                    runs[key].append(cosim(_project(tmp, node, steps), tmp, timeout))
                except RuntimeError as exc:
                    raise RuntimeError(f"{what} co-simulation failed: {exc}") from None
            try:
                runs["bridge_fmu_cosim_steps_per_s"].append(bridge(tmp, built, steps, timeout, tmp / f"bridge-run-{r}"))
            except RuntimeError as exc:
                raise RuntimeError(f"the bridge FMU's co-simulation failed: {exc}") from None
            floor = run([sys.executable, str(HERE / "_zenoh_floor.py"), "server", f"tcp/127.0.0.1:{free_port()}",
                         "1", str(steps), "auto"], timeout)
            if floor.returncode:
                raise RuntimeError(f"the Zenoh floor failed:\n{floor.stderr[-2000:]}")
            runs["zenoh_floor_steps_per_s"].append(float(floor.stdout.split()[-1]))
            me_step, fmpy_step = model_exchange(ball, steps)
            runs["me_node_step_us"].append(me_step * 1e6)
            runs["fmpy_me_step_us"].append(fmpy_step * 1e6)
    return {key: statistics.median(values) for key, values in runs.items()}


def _manual_table(args: argparse.Namespace, f: dict[str, float]) -> _table.Table:
    py_cosim, fmu_cosim = f["python_node_cosim_steps_per_s"], f["fmu_node_cosim_steps_per_s"]
    me, ref = f["me_node_step_us"], f["fmpy_me_step_us"]
    rows = [["one step of the gain model", f"FMU (pythonfmu via fmpy) {f['fmu_node_step_us']:.1f} µs",
             f"Python node {f['python_node_step_us']:.1f} µs", f"{f['fmu_node_step_us'] / f['python_node_step_us']:.1f}×"],
            ["a one-node co-simulation", f"FMU {1e6 / fmu_cosim:.1f} µs a step", f"Python node {1e6 / py_cosim:.1f} µs",
             f"{py_cosim / fmu_cosim:.2f}×"],
            ["a round trip", f"bridge FMU {1e6 / f['bridge_fmu_cosim_steps_per_s']:.1f} µs",
             f"raw Zenoh {1e6 / f['zenoh_floor_steps_per_s']:.1f} µs",
             f"{f['zenoh_floor_steps_per_s'] / f['bridge_fmu_cosim_steps_per_s']:.2f}×"],
            ["Model Exchange (the bouncing ball, 10 ms)", f"node {me:.1f} µs a step", f"`fmpy.simulate_fmu` {ref:.1f} µs",
             f"{me / ref:.2f}×"]]
    return _table.Table(f"Medians of {args.repeat} interleaved rounds of {args.steps:,} macro steps:",
                        ["what", "measured", "against", "ratio"], rows)


def report(f: dict[str, float]) -> None:
    """Print the figures ``f`` as lines of text, each with its ratio."""
    py_step, fmu_step = f["python_node_step_us"], f["fmu_node_step_us"]
    py_cosim, fmu_cosim = f["python_node_cosim_steps_per_s"], f["fmu_node_cosim_steps_per_s"]
    bridge_rate, floor_rate = f["bridge_fmu_cosim_steps_per_s"], f["zenoh_floor_steps_per_s"]
    print(f"node step alone:   Python {py_step:8.1f} µs   FMU (pythonfmu via fmpy) {fmu_step:8.1f} µs"
          f"   ratio {fmu_step / py_step:.1f}×")
    print(f"one-node co-sim:   Python {py_cosim:8.0f} steps/s   FMU {fmu_cosim:8.0f} steps/s"
          f"   overhead {1e6 / fmu_cosim - 1e6 / py_cosim:+.1f} µs/step")
    print(f"round trip:        raw Zenoh {1e6 / floor_rate:7.1f} µs   hycosim Zenoh node {1e6 / py_cosim:7.1f} µs"
          f"   bridge FMU (C importer, TCP gateway) {1e6 / bridge_rate:7.1f} µs"
          f"   bridge/raw {floor_rate / bridge_rate:.2f}×")
    me, ref = f["me_node_step_us"], f["fmpy_me_step_us"]
    print(f"Model Exchange:    node (CVode) {me:8.1f} µs/step   fmpy.simulate_fmu {ref:8.1f} µs/step"
          f"   ratio {me / ref:.2f}×   overhead {me - ref:+.1f} µs/step")


if __name__ == "__main__":
    main()
