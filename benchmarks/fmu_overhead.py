"""FMU overheads per macro step, measured in one run.

1. A model as an FMU node (pythonfmu, through fmpy) against the same model as a plain
   Python node: both in-process (the node's step call alone) and in a whole
   co-simulation over Zenoh (one node, so the barrier's round trip is the rest).
2. A generated native bridge FMU driven by a C-only importer through the TCP gateway,
   against a Zenoh Python node and the raw Zenoh round trip (benchmarks/_zenoh_floor.py).

    python benchmarks/fmu_overhead.py [--steps 3000] [--timeout 300] [--json]

Each co-simulation has ``--timeout`` seconds; past it, its processes are killed (all of
them: benchmarks/_procs.py) and the benchmark stops with a message naming the measurement.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

from fmu_bridge.bridge_fmu import build_bridge_fmu  # noqa: E402
from fmu_bridge.config import load_project, parse_project  # noqa: E402
from fmu_bridge.model_fmu import build_model_fmu  # noqa: E402

from _procs import free_port, kill_group, run, start  # noqa: E402


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
    res = run([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", str(tmp / "runs"), "--no-progress"],
              timeout, cwd=REPO)
    if res.returncode:
        raise RuntimeError(res.stderr)
    metas = sorted((tmp / "runs").glob("bench-*/meta.json"), key=lambda p: p.stat().st_mtime)
    return float(json.loads(metas[-1].read_text())["steps_per_s"])


def in_process(fmu: Path, steps: int) -> tuple[float, float]:
    from clients.fmu_node import FmuNode
    from clients.node import NodeContext
    from clients.reference.gain import Gain

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


def bridge(tmp: Path, steps: int, timeout: float) -> float:
    node = {"nodeName": "tool", "UID": 9, "input": ["u"], "output": ["y"]}
    cfg = _project(tmp, node, steps)
    built = build_bridge_fmu(load_project(cfg), "tool", tmp / "fmus")
    with zipfile.ZipFile(built.path) as zf:
        zf.extractall(tmp / "bridge")
    exe = tmp / "importer"
    headers = Path(__import__("fmpy").__file__).parent / "c-code"
    subprocess.run(["gcc", "-O2", f"-I{headers}", "-o", str(exe), str(REPO / "tests" / "c" / "importer.c"), "-ldl"],
                   check=True)
    doc = json.loads(cfg.read_text())
    server = start([sys.executable, "-m", "hycosim", "server", str(cfg), "--run-dir", str(tmp / "bridge-run")],
                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=REPO)
    deadline = time.monotonic() + timeout  # one limit for the importer and the server together
    try:
        imp = run([str(exe), str(tmp / "bridge" / "binaries" / "linux64" / "hycosim_tool.so"), built.guid,
                   (tmp / "bridge").as_uri(), doc["gatewayIP"], str(steps), "1.0"], timeout)
        _, server_err = server.communicate(timeout=max(0.0, deadline - time.monotonic()))
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"timed out after {timeout:g} s (--timeout): the bridge FMU's server") from None
    finally:
        if server.poll() is None:
            kill_group(server)
            server.communicate()
    if imp.returncode or server.returncode:
        raise RuntimeError(imp.stderr + server_err)
    return float(json.loads((tmp / "bridge-run" / "meta.json").read_text())["steps_per_s"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per co-simulation before it is killed")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    try:
        figures = measure(args.steps, args.timeout)
    except RuntimeError as exc:
        raise SystemExit(f"fmu_overhead: {exc}") from None
    if args.json:
        print(json.dumps(figures))
        return
    report(figures)


def measure(steps: int, timeout: float) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as tmpname:
        tmp = Path(tmpname)
        fmu = build_model_fmu(REPO / "tests" / "models" / "gain_model.py", tmp)
        py_step, fmu_step = in_process(fmu, steps)
        try:
            py_cosim = cosim(_project(tmp, {"nodeName": "py", "UID": 1, "model": "gain",
                                            "parameters": {"k": 0.5, "b": 1.0}, "input": ["u"], "output": ["y"]},
                                      steps), tmp, timeout)
        except RuntimeError as exc:
            raise RuntimeError(f"the Python node's co-simulation failed: {exc}") from None
        try:
            fmu_cosim = cosim(_project(tmp, {"nodeName": "fmu", "UID": 1, "fmu": str(fmu),
                                             "input": ["u"], "output": ["y"]}, steps), tmp, timeout)
        except RuntimeError as exc:
            raise RuntimeError(f"the FMU node's co-simulation failed: {exc}") from None
        try:
            bridge_rate = bridge(tmp, steps, timeout)
        except RuntimeError as exc:
            raise RuntimeError(f"the bridge FMU's co-simulation failed: {exc}") from None
        floor = run([sys.executable, str(HERE / "_zenoh_floor.py"), "server", f"tcp/127.0.0.1:{free_port()}",
                     "1", str(steps), "auto"], timeout)
        if floor.returncode:
            raise RuntimeError(f"the Zenoh floor failed:\n{floor.stderr[-2000:]}")
        floor_rate = float(floor.stdout.split()[-1])
    return {
        "python_node_step_us": py_step * 1e6, "fmu_node_step_us": fmu_step * 1e6,
        "python_node_cosim_steps_per_s": py_cosim, "fmu_node_cosim_steps_per_s": fmu_cosim,
        "bridge_fmu_cosim_steps_per_s": bridge_rate, "zenoh_floor_steps_per_s": floor_rate,
    }


def report(f: dict[str, float]) -> None:
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


if __name__ == "__main__":
    main()
