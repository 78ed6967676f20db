"""Generated native bridge FMUs: validation, fmpy and a C-only importer on the barrier, gateway refusals."""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from hycosim.bridge import gateway_protocol as gp
from hycosim.bridge.bridge_fmu import BridgeBuildError, build_bridge_fmu
from hycosim.core.config import load_project
from tests.helpers import REPO, column, env, hycosim, meta, read_rows, reap, spawn, write_project

FMI_HEADERS = Path(__import__("fmpy").__file__).parent / "c-code"


def _project(tmp_path: Path, stop: float = 1.0, tool_step: float | None = None, **cosim) -> Path:
    """The bridge FMU's node ``tool`` (stepping every ``tool_step`` s, if given) reading a clock."""
    settings = {"stepSize": 0.1, "stopTime": stop, "attachTimeout": 30.0, "stepTimeout": 10.0}
    settings.update(cosim)
    tool = {"nodeName": "tool", "UID": 7, "input": ["u"], "output": [{"name": "y", "unit": "m", "start": 1.5}]}
    if tool_step is not None:
        tool["stepSize"] = tool_step
    cfg = write_project(tmp_path / "p.json", [
        tool,
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
    ], [{"from": "clock.y", "to": "tool.u"}], cosim=settings, name="bridge")
    doc = json.loads(cfg.read_text())
    host, port = doc["serverIP"].split("/")[1].split(":")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        doc["gatewayIP"] = f"127.0.0.1:{s.getsockname()[1]}"
    cfg.write_text(json.dumps(doc))
    return cfg


def _gateway(cfg: Path) -> tuple[str, int]:
    host, port = json.loads(cfg.read_text())["gatewayIP"].split(":")
    return host, int(port)


def test_every_generated_fmu_validates_and_declares_exactly_the_ports(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "a", "UID": 1, "input": ["u", {"name": "n", "type": "Integer", "start": 3}],
         "output": [{"name": "y", "unit": "rad"}, {"name": "ok", "type": "Boolean", "start": True}]},
        {"nodeName": "b-2", "UID": 2, "input": [], "output": ["z"]},
    ], [{"from": "b-2.z", "to": "a.u"}])
    res = hycosim("fmu", "build", str(cfg), "-o", str(tmp_path / "fmus"))
    assert res.returncode == 0, res.stderr
    for name, ins, outs in (("a", ["y", "ok"], ["u", "n", "hycosim_driven"]), ("b-2", ["z"], ["hycosim_driven"])):
        path = tmp_path / "fmus" / f"{name}.fmu"
        assert validate_fmu(str(path)) == []
        md = read_model_description(str(path), validate_model_structure=True, validate_variable_names=True)
        by_causality = {c: [v.name for v in md.modelVariables if v.causality == c] for c in ("input", "output")}
        assert by_causality == {"input": ins, "output": outs}
        params = {v.name: v.start for v in md.modelVariables if v.causality == "parameter"}
        assert set(params) == {"hycosim_server", "hycosim_node", "hycosim_uid", "hycosim_timeout"}
        assert md.coSimulation.modelIdentifier == "hycosim_" + name.replace("-", "_")
        with zipfile.ZipFile(path) as zf:
            names = set(zf.namelist())
        assert {"sources/bridge_fmu.c", "sources/bridge_config.h", "sources/Makefile", "sources/CMakeLists.txt",
                f"binaries/linux64/{md.coSimulation.modelIdentifier}.so"} <= names
    md = read_model_description(str(tmp_path / "fmus" / "a.fmu"))
    starts = {v.name: v.start for v in md.modelVariables}
    assert starts["n"] == "3" and starts["ok"] == "true"
    assert [v.unit for v in md.modelVariables if v.name == "y"] == ["rad"]


def test_sources_in_the_fmu_rebuild_with_their_makefile(tmp_path):
    built = build_bridge_fmu(load_project(_project(tmp_path)), "tool", tmp_path / "fmus")
    with zipfile.ZipFile(built.path) as zf:
        zf.extractall(tmp_path / "x")
    (tmp_path / "x" / "binaries" / "linux64" / "hycosim_tool.so").unlink()
    res = subprocess.run(["make", "-C", str(tmp_path / "x" / "sources")], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "x" / "binaries" / "linux64" / "hycosim_tool.so").stat().st_size > 5000


def test_unsupported_port_types_are_refused_naming_node_and_port(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "cam", "UID": 1, "input": [], "output": [{"name": "frame", "type": "Binary"}]}])
    with pytest.raises(BridgeBuildError, match="node 'cam', port 'frame'"):
        build_bridge_fmu(load_project(cfg), "cam", tmp_path)
    res = hycosim("fmu", "build", str(cfg), "-o", str(tmp_path / "o"))
    assert res.returncode == 2 and "port 'frame'" in res.stderr


def _start(cfg: Path, run_dir: Path):
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    clock = spawn("node", "clock", str(cfg))
    return server, clock


def _finish(procs, timeout=60):
    outs = []
    try:
        for p in procs:
            outs.append(p.communicate(timeout=timeout))
    finally:
        reap(*procs)
    return outs


def _check_exchange(run_dir: Path, u_seen: list[tuple[float, float]]) -> None:
    rows = read_rows(run_dir)
    assert len(rows) == 11 and meta(run_dir)["status"] == "completed"
    clock, tool_u, tool_y, t = column(rows, "clock.y"), column(rows, "tool.u"), column(rows, "tool.y"), column(rows, "t")
    for k in range(10):
        assert abs(tool_y[k] - (2 * t[k] + 1)) < 1e-12  # what the importer set at T_k reached the server
        assert tool_u[k] == clock[k]
        # doStep(T_k) returns the inputs routed at T_k, read by the importer at T_k + H
        assert abs(u_seen[k][0] - t[k + 1]) < 1e-12 and u_seen[k][1] == clock[k]


def test_bridge_fmu_in_fmpy_simulate_fmu_exchanges_exact_values(tmp_path):
    cfg = _project(tmp_path)
    fmu = build_bridge_fmu(load_project(cfg), "tool", tmp_path / "fmus").path
    server, clock = _start(cfg, tmp_path / "run")
    script = f"""
import numpy as np
from fmpy import simulate_fmu
sig = np.array([(t, 2 * t + 1) for t in np.linspace(0, 1, 11)], dtype=[("time", float), ("y", float)])
r = simulate_fmu({str(fmu)!r}, start_time=0, stop_time=1.0, step_size=0.1, output_interval=0.1, input=sig,
                 output=["u"])
for row in r[1:]:
    print(repr(float(row["time"])) + "," + repr(float(row["u"])))
"""
    importer = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, env=env())
    (out, err), (_, serr), _ = _finish([importer, server, clock])
    assert importer.returncode == 0, err
    assert server.returncode == 0, serr
    u_seen = [tuple(map(float, line.split(","))) for line in out.split()]
    _check_exchange(tmp_path / "run", u_seen)


def test_bridge_fmu_tells_the_importer_when_an_event_drives_its_node(tmp_path):
    """hycosim_driven after doStep(T_k) is the mode of the release at T_k: true exactly for the
    steps the server recorded in the event's mode, so the tool's model can follow its inputs."""
    cfg = _project(tmp_path)
    doc = json.loads(cfg.read_text())
    doc["events"] = [{"name": "follow", "when": "clock.y >= 0.3", "drives": "tool", "until": "clock.y >= 0.6"}]
    doc["linkLists"][0]["activeIn"] = ["free", "follow"]
    cfg.write_text(json.dumps(doc))
    fmu = build_bridge_fmu(load_project(cfg), "tool", tmp_path / "fmus").path
    server, clock = _start(cfg, tmp_path / "run")
    script = f"""
from fmpy import simulate_fmu
r = simulate_fmu({str(fmu)!r}, start_time=0, stop_time=1.0, step_size=0.1, output_interval=0.1,
                 output=["hycosim_driven"])
print(" ".join(str(int(row["hycosim_driven"])) for row in r))
"""
    importer = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, env=env())
    (out, err), (_, serr), _ = _finish([importer, server, clock])
    assert importer.returncode == 0, err
    assert server.returncode == 0, serr
    driven = [bool(int(x)) for x in out.split()]
    modes = [row["mode"] for row in read_rows(tmp_path / "run")]
    assert "follow" in modes and "free" in modes[modes.index("follow"):]  # entered and released
    assert driven[0] is False  # before the first doStep
    assert driven[1:] == [m == "follow" for m in modes[:10]]


def test_a_bridge_fmu_reaches_a_server_and_gateway_on_ipv6(tmp_path):
    """serverIP and gatewayIP as [IPv6]:PORT, as the project file allows. Before, the gateway could
    not listen there (the socket was made for IPv4: "Address family for hostname not supported")
    and the FMU took "[::1]" with its brackets for a host name it could not resolve."""
    cfg = _project(tmp_path)
    doc = json.loads(cfg.read_text())
    ports = []
    for _ in range(2):
        with socket.socket(socket.AF_INET6) as s:
            s.bind(("::1", 0))
            ports.append(s.getsockname()[1])
    doc["serverIP"], doc["gatewayIP"] = f"[::1]:{ports[0]}", f"[::1]:{ports[1]}"
    cfg.write_text(json.dumps(doc))
    fmu = build_bridge_fmu(load_project(cfg), "tool", tmp_path / "fmus").path
    server, clock = _start(cfg, tmp_path / "run")
    importer = _importer(fmu, 0.1, 2)
    (out, err), (_, serr), _ = _finish([importer, server, clock])
    assert importer.returncode == 0, err + out
    assert server.returncode == 0, serr
    assert meta(tmp_path / "run")["gateway"] == f"[::1]:{ports[1]}"
    _check_exchange(tmp_path / "run", [tuple(map(float, line.split(","))) for line in out.split()])


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc")
def test_bridge_fmu_in_a_c_only_importer(tmp_path):
    cfg = _project(tmp_path)
    built = build_bridge_fmu(load_project(cfg), "tool", tmp_path / "fmus")
    with zipfile.ZipFile(built.path) as zf:
        zf.extractall(tmp_path / "fmu")
    exe = tmp_path / "importer"
    res = subprocess.run(["gcc", "-O1", f"-I{FMI_HEADERS}", "-o", str(exe), str(REPO / "tests" / "c" / "importer.c"),
                          "-ldl"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    server, clock = _start(cfg, tmp_path / "run")
    host, port = _gateway(cfg)
    importer = subprocess.Popen([str(exe), str(tmp_path / "fmu" / "binaries" / "linux64" / "hycosim_tool.so"),
                                 built.guid, (tmp_path / "fmu" / "resources").as_uri(), f"{host}:{port}", "10", "0.1"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    (out, err), (_, serr), _ = _finish([importer, server, clock])
    assert importer.returncode == 0, err
    assert server.returncode == 0, serr
    _check_exchange(tmp_path / "run", [tuple(map(float, line.split(","))) for line in out.split()])


def _raw_attach(cfg: Path, server: subprocess.Popen, uid: int, name: str = "tool", n_out: int = 1,
                n_in: int = 1) -> tuple[socket.socket, int, bytes]:
    host, port = _gateway(cfg)
    deadline = time.monotonic() + 30
    while True:
        try:
            sock = socket.create_connection((host, port), timeout=10)
            break
        except OSError:
            if server.poll() is not None:
                pytest.fail(f"the server exited ({server.returncode}) before its gateway listened:\n"
                            f"{server.communicate()[1][-3000:]}")
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)
    sock.sendall(gp.hello(uid, name, n_out, n_in))
    kind, payload = gp.read_frame(sock)
    return sock, kind, payload


def test_gateway_refuses_a_wrong_uid_and_counts_it(tmp_path):
    cfg = _project(tmp_path, attachTimeout=8.0)
    server, clock = _start(cfg, tmp_path / "run")
    sock, kind, payload = _raw_attach(cfg, server, uid=99)
    assert kind == gp.REFUSE and payload.decode() == "UID 99 does not own node 'tool'"
    sock.close()
    sock, kind, payload = _raw_attach(cfg, server, uid=7, n_out=3)
    assert kind == gp.REFUSE and "rebuild it from this project" in payload.decode()
    sock.close()
    (_, serr), _ = _finish([server, clock])
    assert server.returncode == 3 and "waiting for node(s) tool to attach" in serr
    assert meta(tmp_path / "run")["dropped_frames"] == {"not owner": 1, "unknown ports": 1}


def test_gateway_truncated_frame_is_counted_and_the_node_is_lost(tmp_path):
    cfg = _project(tmp_path)
    server, clock = _start(cfg, tmp_path / "run")
    sock, kind, _ = _raw_attach(cfg, server, uid=7)
    assert kind == gp.WELCOME
    assert gp.read_frame(sock)[0] == gp.START
    sock.sendall(gp.outputs(0, 0.0, [1.0]))
    assert gp.read_frame(sock)[0] == gp.STEP
    sock.sendall(gp.outputs(1, 0.1, [2.0])[:-5])  # a frame cut short, then the connection ends
    sock.close()
    (_, serr), _ = _finish([server, clock])
    assert server.returncode == 3 and "node 'tool' was lost at step 1" in serr
    m = meta(tmp_path / "run")
    assert m["dropped_frames"] == {"truncated": 1}
    assert len(read_rows(tmp_path / "run")) == 1


def test_gateway_node_disconnecting_mid_step_stops_the_run_naming_it(tmp_path):
    cfg = _project(tmp_path, stop=5.0)
    server, clock = _start(cfg, tmp_path / "run")
    sock, kind, _ = _raw_attach(cfg, server, uid=7)
    assert kind == gp.WELCOME and gp.read_frame(sock)[0] == gp.START
    for k in range(3):
        sock.sendall(gp.outputs(k, 0.1 * k, [float(k)]))
        kind, payload = gp.read_frame(sock)
        assert kind == gp.STEP and gp.parse_step(payload)[0] == k
    sock.close()  # mid-step: released for step 2, never reports step 3
    (_, serr), (_, cerr) = _finish([server, clock])
    assert server.returncode == 3 and "node 'tool' was lost at step 3" in serr
    assert clock.returncode == 5 and "node 'clock': the server stopped the run: node 'tool' was lost" in cerr
    rows = read_rows(tmp_path / "run")
    assert column(rows, "tool.y") == [0.0, 1.0, 2.0]


def test_gateway_drops_forged_releases_and_passes_only_the_servers(tmp_path):
    """The release key is open to anyone on an unsecured network: a STEP whose fields have the
    wrong types, or that gives the bridged node an input of the wrong type, never reaches the FMU
    (nor the Python node beside it); it is counted, and the FMU sees exactly the server's steps.
    A STEP that leaves the bridged node out is not for it (in a multi-rate or Gauss-Seidel run
    the server's own do): it does not reach the FMU either, and is no malformed release."""
    import zenoh

    from hycosim.core import frames
    from hycosim.transport.keys import ProjectKeys
    from hycosim.transport.session import client_config

    cfg = _project(tmp_path, stop=0.5)
    server, clock = _start(cfg, tmp_path / "run")
    sock, kind, _ = _raw_attach(cfg, server, uid=7)
    assert kind == gp.WELCOME and gp.read_frame(sock)[0] == gp.START
    sock.sendall(gp.outputs(0, 0.0, [0.0]))
    assert gp.read_frame(sock)[0] == gp.STEP
    forged = [frames.encode(frames.STEP, 1, "0.1", 0.1, "free", {"tool": [1.0]}, [], {}),
              frames.encode(frames.STEP, 1, 0.1, 0.1, "free", {"tool": ["1.0"]}, [], {}),
              frames.encode(frames.STEP, 1, 0.1, 0.1, "free", {"clock": 5}, [], {})]
    with zenoh.open(client_config(json.loads(cfg.read_text())["serverIP"])) as session:
        for payload in forged:
            session.put(ProjectKeys("bridge").down, payload, congestion_control=zenoh.CongestionControl.BLOCK)
        time.sleep(0.3)
    steps = [0]
    for k in range(1, 6):
        sock.sendall(gp.outputs(k, 0.1 * k, [float(k)]))
        kind, payload = gp.read_frame(sock)
        if kind != gp.STEP:
            break
        steps.append(gp.parse_step(payload)[0])
    assert kind == gp.STOP and steps == [0, 1, 2, 3, 4]
    sock.close()
    (_, serr), _ = _finish([server, clock])
    assert server.returncode == 0 and "Traceback" not in serr
    assert meta(tmp_path / "run")["dropped_frames"] == {"malformed release": 2}


def test_gateway_refuses_an_fmu_for_a_node_already_attached_over_zenoh(tmp_path):
    cfg = _project(tmp_path, attachTimeout=8.0)
    endpoint = json.loads(cfg.read_text())["serverIP"]
    server, clock = _start(cfg, tmp_path / "run")
    deadline = time.monotonic() + 30
    while "attached 1/2" not in (said := hycosim("status", endpoint, "--project", "bridge").stdout):
        assert time.monotonic() < deadline, "clock never attached"
        time.sleep(0.2)
    assert "attached 1/2: clock; waiting for tool" in said, said  # who is there, and who is not
    sock, kind, payload = _raw_attach(cfg, server, uid=1, name="clock", n_out=2, n_in=0)
    sock.close()
    assert kind == gp.REFUSE and payload.decode() == (
        "node 'clock' is already attached: a process on Zenoh holds its liveliness token")
    (_, serr), _ = _finish([server, clock])
    assert server.returncode == 3 and "waiting for node(s) tool to attach" in serr
    assert meta(tmp_path / "run")["dropped_frames"] == {"not owner": 1}


def test_a_python_node_is_refused_for_a_node_attached_through_the_gateway(tmp_path):
    """The gateway holds the liveliness token of each bridge FMU it serves, so a process that
    starts for the same node over Zenoh is refused at attach, and the run goes on with the FMU."""
    cfg = _project(tmp_path, stop=0.3)
    doc = json.loads(cfg.read_text())
    doc["nodeLists"][0]["model"] = "gain"  # so that a Python process could run the node too
    cfg.write_text(json.dumps(doc))
    server, clock = _start(cfg, tmp_path / "run")
    sock, kind, _ = _raw_attach(cfg, server, uid=7)
    assert kind == gp.WELCOME and gp.read_frame(sock)[0] == gp.START
    second = hycosim("node", "tool", str(cfg), timeout=60)
    assert second.returncode == 3, second.stderr
    assert "node 'tool' is already attached" in second.stderr and "Traceback" not in second.stderr
    steps = []
    for k in range(10):
        sock.sendall(gp.outputs(k, 0.1 * k, [float(k)]))
        kind, payload = gp.read_frame(sock)
        if kind != gp.STEP:
            break
        steps.append(gp.parse_step(payload)[0])
    assert kind == gp.STOP and steps == [0, 1, 2]
    sock.close()
    (_, serr), _ = _finish([server, clock])
    assert server.returncode == 0, serr
    assert column(read_rows(tmp_path / "run"), "tool.y") == [0.0, 1.0, 2.0, 3.0]
    assert meta(tmp_path / "run")["dropped_frames"] == {}


def test_a_bridge_fmu_attaching_mid_run_is_told_the_run_is_under_way(tmp_path):
    """Within linkGrace the relay waits for a lost node; a new bridge FMU instance for it has
    lost the node's state (and its START is gone), so it is refused at HELLO rather than left
    waiting for a START that never comes, and the run stops naming the node after the grace."""
    cfg = _project(tmp_path, stop=5.0, linkGrace=2.0)
    server, clock = _start(cfg, tmp_path / "run")
    sock, kind, _ = _raw_attach(cfg, server, uid=7)
    assert kind == gp.WELCOME and gp.read_frame(sock)[0] == gp.START
    for k in range(2):
        sock.sendall(gp.outputs(k, 0.1 * k, [float(k)]))
        assert gp.read_frame(sock)[0] == gp.STEP
    sock.close()
    again, kind, payload = _raw_attach(cfg, server, uid=7)
    again.close()
    assert kind == gp.REFUSE and payload.decode() == (
        "node 'tool': the run was already under way when it attached; a node joins before the run starts: "
        "start the run again")
    (_, serr), _ = _finish([server, clock])
    assert server.returncode == 3 and "did not come back within the link grace of 2 s" in serr
    assert meta(tmp_path / "run")["dropped_frames"] == {"late attach": 1}
    assert column(read_rows(tmp_path / "run"), "tool.y") == [0.0, 1.0]


def test_a_malformed_hello_is_named_by_what_is_wrong_with_it():
    from hycosim.bridge import gateway_protocol as gp

    good = gp.hello(7, "rod", 4, 2)[gp.HEADER.size:]
    assert gp.parse_hello(good) == (7, "rod", 4, 2)
    cases = {
        good[:4]: "4 bytes, shorter than its 6-byte start",
        b"\x01\x00\x00\x00\xff\xff": "a 65535-byte name and two counts need 65545 bytes, it has 6",
        good + b"\x00": "a 3-byte name and two counts need 13 bytes, it has 14",
        good[:6] + b"\xff\xfe\xfd" + good[9:]: "the node name is not UTF-8",
    }
    for payload, message in cases.items():
        with pytest.raises(gp.ProtocolError, match=message):
            gp.parse_hello(payload)


def _importer(fmu: Path, step: float | None, slope: float) -> subprocess.Popen:
    """fmpy's simulate_fmu over [0, 1] s with steps of ``step`` (None: the times of the FMU's
    default experiment), setting the FMU's y to slope * t + 1 and printing, after each doStep,
    the end of the step and the u it read."""
    times = "" if step is None else f"start_time=0, stop_time=1.0, step_size={step}, output_interval={step},"
    script = f"""
import numpy as np
from fmpy import simulate_fmu
sig = np.array([(t, {slope} * t + 1) for t in np.linspace(0, 1, 11)], dtype=[("time", float), ("y", float)])
r = simulate_fmu({str(fmu)!r}, {times} input=sig, output=["u"])
for row in r[1:]:
    print(repr(float(row["time"])) + "," + repr(float(row["u"])))
"""
    return subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env())


def test_a_bridge_fmu_slower_than_the_base_step_steps_at_its_own_rate(tmp_path):
    """A bridge FMU whose node steps every 2 base steps takes the releases of its own steps only
    (a release that leaves it out, the clock's alone, is not a malformed one), with its own step
    size, and answers each with the label the server expects. Before, the gateway dropped the
    clock's releases as malformed, and the run timed out at step 4. The importer is given no
    times: the FMU's default experiment is the run's, with the node's step."""
    cfg = _project(tmp_path, tool_step=0.2)
    fmu = build_bridge_fmu(load_project(cfg), "tool", tmp_path / "fmus").path
    server, clock = _start(cfg, tmp_path / "run")
    experiment = read_model_description(str(fmu)).defaultExperiment
    assert (experiment.startTime, experiment.stopTime, experiment.stepSize) == ("0.0", "1.0", "0.2")
    importer = _importer(fmu, None, 2)
    (out, err), (_, serr), _ = _finish([importer, server, clock])
    assert importer.returncode == 0, err
    assert server.returncode == 0, serr
    assert "but the co-simulation step is" not in err  # START gave the bridge FMU its own step
    m = meta(tmp_path / "run")
    assert m["status"] == "completed" and not m.get("dropped_frames")
    rows = read_rows(tmp_path / "run")
    t, clock_y, tool_y = column(rows, "t"), column(rows, "clock.y"), column(rows, "tool.y")
    assert [r["stepped"] for r in rows[:4]] == ["tool clock", "clock", "tool clock", "clock"]
    # The tool's outputs at the start of each of its steps, held over the base point inside it;
    # at the last point, what the importer set before its last step (it sets nothing newer).
    assert tool_y == pytest.approx([2 * t[min(k - k % 2, 8)] + 1 for k in range(11)])
    # doStep(T) returns the inputs routed at T (the clock there), read by the importer at T + 0.2.
    u_seen = [float(x) for line in out.split() for x in line.split(",")]
    assert u_seen == pytest.approx([x for k in range(0, 10, 2) for x in (t[k + 2], clock_y[k])])


def test_a_bridge_fmus_last_step_cut_at_the_stop_time_is_the_releases_step(tmp_path):
    """A node stepping 0.3 s in a 1.0 s run: the server's last release of it is 0.1 s long, and
    an importer stepping to the same stop time cuts its last doStep to 0.1 s too. The FMU checks
    doStep's h against the release's, not START's 0.3 s, and its last successful time is where
    the release ended. Before, it warned "doStep h=0.1 but the co-simulation step is 0.3" and
    said 1.2 s."""
    cfg = _project(tmp_path, tool_step=0.3)
    fmu = build_bridge_fmu(load_project(cfg), "tool", tmp_path / "fmus").path
    server, clock = _start(cfg, tmp_path / "run")
    script = f"""
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2LastSuccessfulTime
md = read_model_description({str(fmu)!r})
vr = {{v.name: v.valueReference for v in md.modelVariables}}
fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract({str(fmu)!r}),
                modelIdentifier=md.coSimulation.modelIdentifier, instanceName="tool")
fmu.instantiate()
fmu.setupExperiment(startTime=0.0, stopTime=1.0)
fmu.enterInitializationMode()
fmu.exitInitializationMode()
t = 0.0
while t < 1.0 - 1e-9:
    h = min(0.3, 1.0 - t)
    fmu.setReal([vr["y"]], [2 * t + 1])
    fmu.doStep(t, h)
    t += h
    print("step", repr(h), repr(fmu.getRealStatus(fmi2LastSuccessfulTime)), repr(fmu.getReal([vr["u"]])[0]))
fmu.terminate()
fmu.freeInstance()
"""
    importer = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, env=env())
    (out, err), (_, serr), _ = _finish([importer, server, clock])
    assert importer.returncode == 0, err
    assert server.returncode == 0, serr
    assert "co-simulation step" not in out + err  # fmpy's logger prints the FMU's warnings
    steps = [tuple(map(float, line.split()[1:])) for line in out.splitlines() if line.startswith("step ")]
    assert [h for h, _, _ in steps] == pytest.approx([0.3, 0.3, 0.3, 0.1])
    assert [done for _, done, _ in steps] == pytest.approx([0.3, 0.6, 0.9, 1.0])
    rows = read_rows(tmp_path / "run")
    t, clock_y = column(rows, "t"), column(rows, "clock.y")
    assert [u for _, _, u in steps] == pytest.approx([clock_y[k] for k in (0, 3, 6, 9)])
    m = meta(tmp_path / "run")
    assert m["status"] == "completed" and not m.get("dropped_frames")
    # The outputs the importer set before each step, held over the base points inside it; at
    # the last point (1.0 s), what it set before its last step.
    assert column(rows, "tool.y") == pytest.approx([2 * t[min(k - k % 3, 9)] + 1 for k in range(11)])


def test_two_bridge_fmus_step_in_gauss_seidel_order_each_on_the_others_new_outputs(tmp_path):
    """Gauss-Seidel releases one node at a time; with two bridge FMUs each release leaves the
    other out. The second steps on the first's outputs at the end of the same macro step. Before,
    the gateway dropped every release as malformed (each lacked one of them) and the run timed out."""
    cfg = _project(tmp_path, coupling="gauss-seidel")
    doc = json.loads(cfg.read_text())
    doc["nodeLists"].append({"nodeName": "tool2", "UID": 8, "input": ["u"], "output": ["y"]})
    doc["nodeNum"] = 3
    doc["linkLists"].append({"from": "tool.y", "to": "tool2.u"})
    doc["linkNum"] = 2
    cfg.write_text(json.dumps(doc))
    loaded = load_project(cfg)
    assert loaded.coupling.order == ("clock", "tool", "tool2")
    server, clock = _start(cfg, tmp_path / "run")
    first = _importer(build_bridge_fmu(loaded, "tool", tmp_path / "fmus").path, 0.1, 2)
    second = _importer(build_bridge_fmu(loaded, "tool2", tmp_path / "fmus").path, 0.1, 3)
    (out1, err1), (out2, err2), (_, serr), _ = _finish([first, second, server, clock])
    assert first.returncode == 0, err1
    assert second.returncode == 0, err2
    assert server.returncode == 0, serr
    m = meta(tmp_path / "run")
    assert m["status"] == "completed" and not m.get("dropped_frames")
    seen1 = [float(x) for line in out1.split() for x in line.split(",")]
    seen2 = [float(x) for line in out2.split() for x in line.split(",")]
    t = column(read_rows(tmp_path / "run"), "t")
    # tool steps on the clock's new outputs (y = t), tool2 on tool's (y = 2t + 1), both at T + H
    # (Jacobi would give each the outputs at T). tool's at the last point: what it set before its
    # last step, as its importer sets nothing newer.
    assert seen1 == pytest.approx([x for k in range(10) for x in (t[k + 1], t[k + 1])])
    assert seen2 == pytest.approx([x for k in range(10) for x in (t[k + 1], 2 * t[min(k + 1, 9)] + 1)])


def test_a_multi_rate_run_with_a_bridge_fmu_releases_every_base_point_and_says_why(tmp_path):
    """The links would let releases span 2 base steps (the clock steps every 0.2 s), but a bridge
    FMU behind the gateway takes one release at a time: the run releases every base point and
    meta.json names the node; the values are a multi-rate run's."""
    cfg = _project(tmp_path)
    doc = json.loads(cfg.read_text())
    doc["nodeLists"][1]["stepSize"] = 0.2
    cfg.write_text(json.dumps(doc))
    assert load_project(cfg).coupling.batch == 2
    fmu = build_bridge_fmu(load_project(cfg), "tool", tmp_path / "fmus").path
    server, clock = _start(cfg, tmp_path / "run")
    script = f"""
from fmpy import simulate_fmu
simulate_fmu({str(fmu)!r}, start_time=0, stop_time=1.0, step_size=0.1, output_interval=0.1)
"""
    importer = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, env=env())
    (_, err), (_, serr), _ = _finish([importer, server, clock])
    assert importer.returncode == 0, err
    assert server.returncode == 0, serr
    run = tmp_path / "run"
    m = meta(run)
    assert m["coupling"].endswith("one release per base point (tool cannot take batched steps)")
    assert m["messages"]["releases"] == 10
    rows = read_rows(run)
    clock_y, tool_u = column(rows, "clock.y"), column(rows, "tool.u")
    assert [r["stepped"] for r in rows[:4]] == ["tool clock", "tool", "tool clock", "tool"]
    # The clock's output holds over its 0.2 s steps; the tool reads it at every base point.
    assert clock_y[:5] == pytest.approx([0.0, 0.0, 0.2, 0.2, 0.4]) and tool_u[:5] == clock_y[:5]


@pytest.mark.parametrize("timeout", [0.0, -1.0, 1e300])
def test_a_bridge_fmu_refuses_a_timeout_that_would_leave_a_wait_without_bound(tmp_path, capsys, timeout):
    """hycosim_timeout bounds every wait of the FMU on the server. 0 made its socket's waits endless
    (SO_RCVTIMEO 0), a negative one was not set at all, and 1e300 made the attach deadline
    undefined: the FMU refuses them when they are set, naming the range. A project whose timeouts
    add up past the range gives the FMU the range's end, which it takes."""
    cfg = _project(tmp_path, attachTimeout=1e6)  # and 10 s to step: past the range
    fmu = build_bridge_fmu(load_project(cfg), "tool", tmp_path / "fmus").path
    assert validate_fmu(str(fmu)) == []
    start = [v for v in read_model_description(str(fmu)).modelVariables if v.name == "hycosim_timeout"][0]
    assert float(start.start) == 1e6 and (float(start.min), float(start.max)) == (0.001, 1e6)
    from fmpy import simulate_fmu

    with pytest.raises(Exception, match="fmi2SetReal failed"):
        simulate_fmu(str(fmu), start_time=0, stop_time=0.1, step_size=0.1, start_values={"hycosim_timeout": timeout})
    assert f"hycosim_timeout = {timeout:g} s: give 0.001 to 1e+06 s" in capsys.readouterr().out
