"""Faults: lost nodes, malformed frames, nodes that never attach, Ctrl-C, broken node models."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import msgpack
import pytest
import zenoh

from hycosim.core import frames
from hycosim.transport.keys import ProjectKeys
from hycosim.transport.session import client_config
from tests.helpers import hycosim, kill_process, meta, read_rows, reap, spawn, wait_for, write_project


def _pair(tmp_path, **cosim):
    settings = {"stepSize": 0.01, "stopTime": 3.0, "realTime": True, "stepTimeout": 5.0, "attachTimeout": 20.0}
    settings.update(cosim)
    return write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}], cosim=settings, name="faults")


def _endpoint(cfg):
    return json.loads(cfg.read_text())["serverIP"]


def _steps_on_disk(run_dir):
    path = run_dir / "values.csv"
    return len(read_rows(run_dir)) if path.exists() else 0


def test_node_killed_mid_run_stops_with_its_name_and_step(tmp_path):
    cfg = _pair(tmp_path)
    run_dir = tmp_path / "run"
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = {n: spawn("node", n, str(cfg)) for n in ("clock", "g")}
    try:
        wait_for(lambda: _steps_on_disk(run_dir) > 30, 30, "30 steps")
        nodes["g"].send_signal(signal.SIGKILL)
        killed_at = time.monotonic()
        _, err = server.communicate(timeout=30)
        assert time.monotonic() - killed_at < 5  # noticed through liveliness, not a step timeout
        assert server.returncode == 3
        assert "node 'g' was lost at step" in err
        assert "Traceback" not in err
        m = meta(run_dir)
        assert m["status"] == "failed" and "node 'g' was lost" in m["reason"]
        rows = read_rows(run_dir)
        assert len(rows) >= 30 and all(r["step"] == str(i) for i, r in enumerate(rows))
        step = int(m["reason"].split("at step ")[1].split()[0])
        assert len(rows) == step  # every step before the loss is on disk, none after
        assert nodes["clock"].wait(timeout=20) == 5  # told the run failed
    finally:
        reap(server, *nodes.values())


def test_server_killed_mid_run_leaves_a_readable_run_and_the_nodes_stop(tmp_path):
    cfg = _pair(tmp_path, linkGrace=1.0)
    run_dir = tmp_path / "run"
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = {n: spawn("node", n, str(cfg)) for n in ("clock", "g")}
    try:
        wait_for(lambda: _steps_on_disk(run_dir) > 30, 30, "30 steps")
        server.send_signal(signal.SIGKILL)
        server.wait(timeout=10)
        for name, proc in nodes.items():
            _, err = proc.communicate(timeout=20)  # the link grace, then they give up
            assert proc.returncode == 3, err
            assert f"node {name!r}: the server went away" in err and "Traceback" not in err
        rows = read_rows(run_dir)
        assert len(rows) >= 30 and [r["step"] for r in rows] == [str(i) for i in range(len(rows))]
        res = hycosim("report", str(run_dir), "--json")
        assert res.returncode == 0, res.stderr
        summary = json.loads(res.stdout)
        assert summary["status"] == "running"  # the server never closed the run
        assert summary["steps"] == len(read_rows(run_dir, "timing.csv")) >= 30
        res = hycosim("plot", str(run_dir), "g.y", "-o", str(tmp_path / "g.png"))
        assert res.returncode == 0, res.stderr
    finally:
        reap(server, *nodes.values())


def test_a_node_with_another_version_of_the_project_file_stops_the_run_naming_its_ports(tmp_path):
    cfg = _pair(tmp_path, stepTimeout=30.0)
    stale = json.loads(cfg.read_text())
    stale["nodeLists"][1]["input"] = []  # g, as an older file had it, before it was fed by the clock
    stale["linkLists"], stale["linkNum"] = [], 0
    stale_cfg = tmp_path / "stale.json"
    stale_cfg.write_text(json.dumps(stale))
    run_dir = tmp_path / "run"
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = [spawn("node", "clock", str(cfg)), spawn("node", "g", str(stale_cfg))]
    try:
        _, err = server.communicate(timeout=20)  # well before the step timeout of 30 s
        assert server.returncode == 3
        assert ("node 'g' attached with another version of its entry in the project file: its inputs are "
                "none, the server's u:Real. Give every process the same project file") in err
        for p in nodes:
            _, node_err = p.communicate(timeout=20)
            assert p.returncode == 5 and "another version of its entry" in node_err, node_err
    finally:
        reap(server, *nodes)


def test_malformed_frames_are_dropped_counted_and_the_run_goes_on(tmp_path):
    cfg = _pair(tmp_path, stopTime=2.0)
    run_dir = tmp_path / "run"
    endpoint = _endpoint(cfg)
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = [spawn("node", n, str(cfg)) for n in ("clock", "g")]
    keys = ProjectKeys("faults")
    try:
        wait_for(lambda: _steps_on_disk(run_dir) > 10, 30, "10 steps")
        with zenoh.open(client_config(endpoint)) as session:
            bad = [
                (keys.up("g"), os.urandom(40)),                                      # random bytes
                (keys.up("g"), msgpack.packb({"not": "a frame"})),                   # not an array
                (keys.up("g"), msgpack.packb([99, frames.OUTPUTS, 2, 1, 0.0, [1.0]])),  # wrong version
                (keys.up("g"), frames.encode(frames.OUTPUTS, 2, 10**6, 0.0, ["text"])),  # wrong type
                (keys.up("g"), frames.encode(frames.OUTPUTS, 2, 10**6, 0.0, [1.0, 2.0])),  # unknown ports
                (keys.up("g"), frames.encode(frames.OUTPUTS, 2, 0, 0.0, [1.0])),      # step already past
                (keys.up("g"), frames.encode(frames.OUTPUTS, 1, 10**6, 0.0, [1.0])),  # UID of another node
                (keys.up("ghost"), frames.encode(frames.OUTPUTS, 9, 1, 0.0, [1.0])),  # unknown sender
            ]
            for key, payload in bad:
                session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)
            time.sleep(0.3)
        _, err = server.communicate(timeout=30)
        assert server.returncode == 0, err
        m = meta(run_dir)
        assert m["status"] == "completed"
        assert m["dropped_frames"] == {"malformed": 3, "wrong type": 1, "unknown ports": 1,
                                       "step already past": 1, "not owner": 1, "unknown sender": 1}
        rows = read_rows(run_dir)
        assert len(rows) == 201
        # The forged values never reached the routing: g.u is the clock, step by step.
        assert all(r["g.u"] == r["clock.y"] for r in rows)
        log = (run_dir / "server.log.jsonl").read_text()
        assert log.count('"frame dropped"') == 8
    finally:
        reap(server, *nodes)


def _forge_on_the_release_key(tmp_path, payloads: list[bytes], dropped: int) -> None:
    """Run a real-time asynchronous source and a stepping node; write ``payloads`` on the
    server's release key mid-run; check each node logged ``dropped`` drops and ran on."""
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "sensor", "UID": 1, "model": "ramp_source", "async": True, "rate": 20.0, "output": ["y"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "sensor.y", "to": "g.u"}], cosim={"stepSize": 0.01, "stopTime": 2.0, "realTime": True,
                                                   "attachTimeout": 20.0}, name="faults")
    run_dir = tmp_path / "run"
    logs = {n: tmp_path / f"{n}.log.jsonl" for n in ("sensor", "g")}
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = {n: spawn("node", n, str(cfg), "--log-file", str(logs[n])) for n in logs}
    try:
        wait_for(lambda: _steps_on_disk(run_dir) > 10, 30, "10 steps")
        with zenoh.open(client_config(_endpoint(cfg))) as session:
            for payload in payloads:
                session.put(ProjectKeys("faults").down, payload, congestion_control=zenoh.CongestionControl.BLOCK)
            time.sleep(0.3)
        _, err = server.communicate(timeout=30)
        assert server.returncode == 0, err
        for name, proc in nodes.items():
            _, node_err = proc.communicate(timeout=20)
            assert proc.returncode == 0, node_err
            assert logs[name].read_text().count('"frame dropped"') == dropped, name
        assert meta(run_dir)["status"] == "completed" and len(read_rows(run_dir)) == 201
    finally:
        reap(server, *nodes.values())


def test_garbage_on_the_servers_release_key_is_dropped_by_every_node(tmp_path):
    """Nodes read frames anyone on the network may write (without security): a stepping node
    and a real-time asynchronous source both drop garbage, log it, and run to the end."""
    _forge_on_the_release_key(tmp_path, [os.urandom(40), msgpack.packb({"not": "a frame"}),
                                         msgpack.packb([99, frames.STEP])], dropped=3)


def test_forged_releases_with_wrong_contents_are_dropped_by_every_node(tmp_path):
    """Well-formed frames whose contents are not a release a node can act on: a replay carrying
    garbage, an integer, a STOP or a mistyped STEP (one of each per node), and a STEP whose
    fields have the wrong types."""
    mistyped_step = frames.encode(frames.STEP, "7", 0.1, 0.01, "free", {"g": 3.0}, 5, {})
    replays = [frames.encode(frames.REPLAY, name, inner) for name in ("sensor", "g")
               for inner in (os.urandom(24), 7, frames.encode(frames.STOP, 3, "forged"), mistyped_step)]
    # A node ignores replays addressed to the other, so each drops its own four and the STEP.
    _forge_on_the_release_key(tmp_path, [*replays, mistyped_step], dropped=5)


def _second_g(cfg, run_dir, kill_first: bool):
    """Run clock and g; after 20 steps start another g (after SIGKILLing the first, if asked).
    Return the server, the first two nodes, and the second g's exit code and stderr."""
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = [spawn("node", n, str(cfg)) for n in ("clock", "g")]
    try:
        wait_for(lambda: _steps_on_disk(run_dir) > 20, 30, "20 steps")
        if kill_first:
            nodes[1].send_signal(signal.SIGKILL)
            time.sleep(0.5)
        second = spawn("node", "g", str(cfg))
        try:
            _, err = second.communicate(timeout=30)
        finally:
            reap(second)
    except BaseException:
        reap(server, *nodes)
        raise
    return server, nodes, second.returncode, err


def test_a_second_process_for_an_attached_node_is_refused(tmp_path):
    """Launching a node that already runs elsewhere stops the newcomer with a clear message;
    the run it would have corrupted (two processes sending one node's outputs) goes on."""
    run_dir = tmp_path / "run"
    server, nodes, code, err = _second_g(_pair(tmp_path, stopTime=3.0), run_dir, kill_first=False)
    try:
        assert code == 3
        assert "node 'g' is already attached to the server" in err and "Traceback" not in err
        assert server.wait(timeout=30) == 0
        m = meta(run_dir)
        assert m["status"] == "completed" and m["dropped_frames"] == {} and len(read_rows(run_dir)) == 301
        assert all(p.wait(timeout=20) == 0 for p in nodes)
    finally:
        reap(server, *nodes)


def test_a_node_restarted_mid_run_is_told_the_run_is_under_way(tmp_path):
    """A node killed and started again within linkGrace has lost its state: the new process
    sees the replayed step and says HELLO as a restart, and the server, which takes no
    checkpoints to go back to, fails at once naming the node (it used to wait out the grace,
    taking the restart for a link that might come back); the new process ends with its reason."""
    run_dir = tmp_path / "run"
    server, nodes, code, err = _second_g(_pair(tmp_path, stopTime=20.0, linkGrace=10.0), run_dir, kill_first=True)
    try:
        assert code == 5  # FAILED_ELSEWHERE: the server's reason is its message
        assert "node 'g' was started again at step" in err and "checkpoints off" in err and "Traceback" not in err
        refused = time.monotonic()
        _, server_err = server.communicate(timeout=30)
        assert server.returncode == 3 and time.monotonic() - refused < 5.0  # well within the grace of 10 s
        assert "node 'g' was started again at step" in server_err and "the state it had is gone" in server_err
        m = meta(run_dir)
        assert m["status"] == "failed" and m["reattached"] == {"g": 1}
        assert len(read_rows(run_dir)) == m["steps"] >= 20
        assert nodes[0].wait(timeout=20) == 5  # the clock, told the run failed
    finally:
        reap(server, *nodes)


def test_node_that_never_attaches_times_out_naming_it(tmp_path):
    cfg = _pair(tmp_path, attachTimeout=2.0)
    run_dir = tmp_path / "run"
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    node = spawn("node", "clock", str(cfg))
    try:
        _, err = server.communicate(timeout=30)
        assert server.returncode == 3
        assert "timed out after 2 s waiting for node(s) g to attach" in err
        assert "clock" not in err.split("waiting for node(s)")[1].split("to attach")[0]
        assert meta(run_dir)["status"] == "failed"
        _, node_err = node.communicate(timeout=20)  # the server's STOP reaches the node that did attach
        assert node.returncode == 5
        assert "node 'clock': the server stopped the run: timed out" in node_err
        assert "waiting for node(s) g to attach" in node_err
    finally:
        reap(server, node)


def test_a_node_of_another_project_is_told_which_project_the_server_runs(tmp_path):
    cfg = _pair(tmp_path, attachTimeout=30.0)
    other = json.loads(cfg.read_text())
    other["projectName"] = "other"
    other["coSimulation"].update(attachTimeout=1.0, stepTimeout=1.0)  # the node gives up first
    other_cfg = tmp_path / "other.json"
    other_cfg.write_text(json.dumps(other))
    server = spawn("server", str(cfg), "--run-dir", str(tmp_path / "run"))
    try:
        wait_for(lambda: (tmp_path / "run" / "meta.json").exists(), 20, "the server")
        res = hycosim("node", "clock", str(other_cfg), timeout=60)
        assert res.returncode == 3
        assert "node 'clock': no START from the server" in res.stderr
        assert "the server there runs project 'faults', not 'other'" in res.stderr
    finally:
        reap(server)


def test_ctrl_c_shuts_down_cleanly_with_results_flushed(tmp_path):
    cfg = _pair(tmp_path, stopTime=30.0)
    run_dir = tmp_path / "run"
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = [spawn("node", n, str(cfg)) for n in ("clock", "g")]
    try:
        wait_for(lambda: _steps_on_disk(run_dir) > 20, 30, "20 steps")
        server.send_signal(signal.SIGINT)
        _, err = server.communicate(timeout=20)
        assert server.returncode == 130
        assert "Ctrl-C" in err
        m = meta(run_dir)
        assert m["status"] == "interrupted"
        assert len(read_rows(run_dir)) == m["steps"] >= 20
        for p in nodes:
            _, node_err = p.communicate(timeout=20)
            assert p.returncode == 5 and "interrupted by Ctrl-C" in node_err
    finally:
        reap(server, *nodes)


@pytest.mark.parametrize("presses", [1, 2])
def test_ctrl_c_in_a_terminal_stops_an_embedded_run_and_keeps_its_records(tmp_path, presses):
    """A terminal's Ctrl-C reaches the launcher, the server and every node at once; the nodes
    are not blamed. Pressed twice, the launcher stops waiting for the nodes."""
    cfg = _pair(tmp_path, stopTime=60.0)
    runs = tmp_path / "runs"
    run = spawn("run", str(cfg), "--runs-dir", str(runs), "--no-progress", start_new_session=True)
    try:
        wait_for(lambda: runs.exists() and any(_steps_on_disk(d) > 20 for d in runs.iterdir()), 30, "20 steps")
        for press in range(presses):
            time.sleep(0.3 if press else 0.0)
            os.killpg(run.pid, signal.SIGINT)
        _, err = run.communicate(timeout=30)
        assert run.returncode == 130, err
        assert "interrupted by Ctrl-C" in err and "exit status" not in err and "Traceback" not in err
        left = subprocess.run(["pgrep", "-g", str(run.pid)], capture_output=True, text=True).stdout.split()
        assert left == [], f"processes of the run still alive: {left}"
        run_dir = next(runs.iterdir())
        m = meta(run_dir)
        assert m["status"] == "interrupted" and len(read_rows(run_dir)) == m["steps"] >= 20
    finally:
        reap(run)


def test_node_without_server_fails_clearly(tmp_path):
    cfg = _pair(tmp_path, attachTimeout=1.0)
    res = hycosim("node", "clock", str(cfg), timeout=60)
    assert res.returncode == 3
    assert f"cannot open Zenoh session on {_endpoint(cfg)}" in res.stderr
    res = hycosim("node", "nobody", str(cfg), timeout=60)
    assert res.returncode == 2 and "no node named 'nobody'" in res.stderr


def test_ctrl_c_stops_a_node_still_connecting_to_a_server_that_is_not_up(tmp_path):
    """zenoh.open keeps trying for its whole connect timeout (30 s here) without returning to
    Python: Ctrl-C must not wait for it."""
    cfg = _pair(tmp_path, attachTimeout=30.0)
    node = spawn("node", "clock", str(cfg))
    try:
        time.sleep(3.0)
        assert node.poll() is None  # still connecting
        sent = time.monotonic()
        node.send_signal(signal.SIGINT)
        _, err = node.communicate(timeout=20)
        assert node.returncode == 130 and "node 'clock' interrupted by Ctrl-C" in err, err
        assert time.monotonic() - sent < 10, "Ctrl-C waited for the connect timeout"
    finally:
        reap(node)


def test_a_misspelt_parameter_of_a_reference_model_is_refused(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "g", "UID": 1, "model": "gain", "parameters": {"k": 2.0, "offset": 1.0}, "input": ["u"],
         "output": ["y"]}])
    res = hycosim("node", "g", str(cfg), timeout=60)
    assert res.returncode == 2, res.stderr  # bad input, which no restart would mend
    assert "node 'g': model 'gain' has no parameter 'offset' (its parameters: b, k, work_s)" in res.stderr


def test_ctrl_c_while_a_node_loads_its_model_is_an_interruption_not_a_broken_model(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "slow", "UID": 1, "model": "tests.models.interrupted_import:Never", "output": ["y"]}])
    res = hycosim("node", "slow", str(cfg), timeout=60)
    assert res.returncode == 130, res.stderr
    assert "node 'slow' interrupted by Ctrl-C" in res.stderr and "initialization failed" not in res.stderr


def test_embedded_run_reports_a_broken_node_model(tmp_path):
    """A model that is there but fails as its node imports it (what the launcher cannot see
    without importing every model itself)."""
    (tmp_path / "broken.py").write_text("import no_such_module\n")
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "broken", "UID": 2, "model": "broken.py:Thing", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "broken.u"}], cosim={"stopTime": 1.0, "attachTimeout": 30.0})
    started = time.monotonic()
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress", timeout=90)
    assert res.returncode == 3, res.stderr
    assert "node 'broken': cannot load model 'broken.py:Thing': No module named 'no_such_module'" in res.stderr
    assert time.monotonic() - started < 25  # the launcher does not wait out the attach timeout
    assert "clock" not in res.stderr  # stopped by the launcher, not blamed for the failure
    assert "error: broken: node 'broken'" in res.stderr  # one "error:", the launcher's
    run_dir = next((tmp_path / "runs").iterdir())
    assert (run_dir / "meta.json").exists()


def _mount_tmpfs(path, size: str) -> bool:
    path.mkdir()
    if os.geteuid() != 0:
        return False
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                          capture_output=True).returncode == 0


@pytest.mark.parametrize("where", ["--processes", "--in-process"])  # in process, the row writer writes the rows
def test_a_full_disk_stops_the_run_naming_the_file_and_keeps_what_was_recorded(tmp_path, where):
    disk = tmp_path / "disk"
    if not _mount_tmpfs(disk, "400k"):
        pytest.skip("needs root and mount (a small tmpfs stands in for a full disk)")
    try:
        cfg = write_project(tmp_path / "p.json", [
            {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
            {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
        ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 1.0, "stopTime": 50000.0}, name="full")
        res = hycosim("run", str(cfg), where, "--runs-dir", str(disk), "--no-progress")
        assert res.returncode == 3, res.stdout + res.stderr
        assert "cannot write the run's records at step" in res.stderr and "No space left on device" in res.stderr
        assert "Traceback" not in res.stderr and "internal error" not in res.stderr
        run = next(disk.iterdir())
        m = meta(run)
        assert m["status"] == "failed" and "No space left on device" in m["reason"] and m["steps"] > 100
        assert not (run / ".reserve").exists()
        # every row taken before the disk filled is on disk, in order, with the right values
        rows = read_rows(run)
        assert m["steps"] - 1 <= len(rows) <= m["steps"]
        assert [int(r["step"]) for r in rows] == list(range(len(rows)))
        assert all(float(rows[k]["g.y"]) == float(rows[k - 1]["clock.y"]) for k in range(1, len(rows)))
        for node in ("clock", "g") if where == "--processes" else ():  # in process the nodes have no stderr
            assert "the server stopped the run: cannot write the run's records" in (
                run / f"node-{node}.stderr.txt").read_text()
        assert hycosim("report", str(run)).returncode == 0
        # a disk already full: refused before the run starts, naming the folder
        fd = os.open(disk / "filler", os.O_WRONLY | os.O_CREAT)
        try:
            while os.write(fd, bytes(4096)):
                pass
        except OSError:
            pass
        finally:
            os.close(fd)
        res = hycosim("run", str(cfg), where, "--runs-dir", str(disk), "--no-progress")
        assert res.returncode == 3 and "cannot start the run's records in" in res.stderr
        assert "needs 256 KiB free to start" in res.stderr and "Traceback" not in res.stderr
    finally:
        subprocess.run(["umount", str(disk)], capture_output=True)


def test_a_node_that_crashes_in_native_code_is_reported_with_its_signal_and_stack(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "crash", "UID": 2, "model": "tests.models.crashing_model:Crashing", "output": ["y"]},
    ], cosim={"stepSize": 0.01, "stopTime": 1.0})
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress", timeout=90)
    assert res.returncode == 3
    run_dir = next((tmp_path / "runs").iterdir())
    assert "node 'crash' was lost at step" in res.stderr
    assert f"node crash: its process died of SIGSEGV (the Python stack at that moment: {run_dir}" in res.stderr
    stack = (run_dir / "node-crash.stderr.txt").read_text()
    assert "Fatal Python error: Segmentation fault" in stack and 'crashing_model.py", line 14 in step' in stack
    assert "clock" not in res.stderr.replace(str(run_dir), "")
    assert len(read_rows(run_dir)) >= 5  # the steps before the crash are on disk


@pytest.mark.parametrize("where", ["--processes", "--in-process"])
def test_nan_outputs_are_routed_and_recorded_and_the_first_on_each_port_is_reported(tmp_path, where):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "src", "UID": 1, "model": "tests.models.nan_model:Diverging", "output": ["y"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "src.y", "to": "g.u"}], cosim={"stepSize": 0.01, "stopTime": 0.3})
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress", where, timeout=90)
    assert res.returncode == 0, res.stderr
    run_dir = next((tmp_path / "runs").iterdir())
    rows = read_rows(run_dir)
    first_nan = {port: next(k for k, r in enumerate(rows) if r[port] == "nan") for port in ("src.y", "g.y")}
    assert first_nan == {"src.y": 10, "g.y": 11}  # one Jacobi step later downstream
    noted = meta(run_dir)["non_finite"]
    assert {port: at["step"] for port, at in noted.items()} == first_nan
    assert all(abs(at["t"] - float(rows[at["step"]]["t"])) < 1e-9 for at in noted.values())
    expected = "NaN or infinite values, first on each port: src.y at step 10 (t=0.1 s), g.y at step 11 (t=0.11 s)"
    assert expected in res.stdout
    report = hycosim("report", str(run_dir))
    assert report.returncode == 0 and expected in report.stdout
    assert hycosim("plot", str(run_dir), "-o", str(tmp_path / "p.png")).returncode == 0


def test_a_node_whose_native_teardown_aborts_at_exit_still_ends_with_its_outcome(tmp_path):
    """A node process is judged by its run, not by libraries tearing down after it: a model
    whose library aborts at exit (as one FMU's teardown once did) leaves a completed run."""
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "late", "UID": 2, "model": "tests.models.exit_abort_model:AbortsAtExit", "output": ["y"]},
    ], cosim={"stepSize": 0.01, "stopTime": 0.2})
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress", timeout=90)
    assert res.returncode == 0, res.stderr
    run_dir = next((tmp_path / "runs").iterdir())
    assert meta(run_dir)["status"] == "completed" and len(read_rows(run_dir)) == 21
    assert "node 'late' finished after 20 steps" in (run_dir / "node-late.stderr.txt").read_text()


def test_a_node_whose_log_file_cannot_be_opened_stops_the_started_server_and_names_the_file(tmp_path):
    """The launcher starts the server, then each node with its log file in the run's folder. A
    node it cannot start (here: its log file's path is over the system's 4,095 bytes, the
    server's files just under) ends the run at once, naming node and file (exit 3), with
    the server stopped rather than left waiting for nodes until its attach timeout."""
    cfg = _pair(tmp_path, attachTimeout=60.0)
    # runs/<project>-<YYYYmmdd-HHMMSS>: a run folder of 4,075 characters, so that
    # server.stderr.txt fits (4,093) and node-clock.stderr.txt does not (4,097).
    runs = str(tmp_path / "runs")
    target = 4075 - 1 - len("faults-20261128-014459")
    while len(runs) < target:
        runs += "/" + "d" * min(200, target - len(runs) - 1)
    assert len(runs) == target
    began = time.monotonic()
    res = hycosim("run", str(cfg), "--runs-dir", runs, "--no-progress", timeout=60)
    took = time.monotonic() - began
    err = " ".join(res.stderr.split())
    assert res.returncode == 3, res.stderr
    assert "error: node 'clock' could not be started: its log file" in err and "node-clock.stderr.txt" in err
    assert "File name too long" in err and "Traceback" not in err
    assert took < 40, f"the launcher took {took:.0f} s: the server waited for its nodes"
    leftover = [pid for pid in os.listdir("/proc") if pid.isdigit() and _cmdline_has(pid, str(cfg))]
    assert leftover == [], "processes of the run still running"
    run_dir = next(Path(runs).iterdir())
    assert meta(run_dir)["status"] == "failed" and "node 'clock' could not be started" in meta(run_dir)["reason"]


def test_a_node_that_cannot_be_started_again_after_it_died_ends_the_run_naming_it(tmp_path):
    """A node killed mid-run is started again (checkpoints on), its log file opened again for
    appending. Where that file cannot be opened (here a folder has taken its place), the run
    ends at once naming node and file (exit 3), not with a traceback from the launcher."""
    cfg = _pair(tmp_path, stopTime=6.0, checkpointEvery=0.5)
    runs = tmp_path / "runs"
    proc = spawn("run", str(cfg), "--runs-dir", str(runs), "--no-progress", "--restarts", "2")
    try:
        wait_for(lambda: any(_steps_on_disk(d) >= 60 for d in runs.glob("*")), 30, "the run's first rows")
        run_dir = next(runs.iterdir())
        log = run_dir / "node-g.stderr.txt"
        log.unlink()
        log.mkdir()
        kill_process(f"hycosim node g {cfg}")
        began = time.monotonic()
        _, err = proc.communicate(timeout=60)
    finally:
        reap(proc)
    err = " ".join(err.split())
    assert proc.returncode == 3, err
    assert f"node 'g' could not be started: its log file {log} cannot be opened (Is a directory)" in err
    assert "Traceback" not in err
    assert time.monotonic() - began < 30
    assert meta(run_dir)["status"] == "failed" and "could not be started" in meta(run_dir)["reason"]
    assert _steps_on_disk(run_dir) >= 60  # what was recorded stays


def _cmdline_has(pid, text):
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return text.encode() in f.read()
    except OSError:
        return False


@pytest.mark.parametrize("where", ["--processes", "--in-process"])
def test_a_run_whose_folder_is_removed_while_it_runs_says_so_in_one_line(tmp_path, where):
    """The run's files are gone when it ends: the command names the folder and the likely cause
    (exit 3), with no traceback."""
    import shutil

    cfg = _pair(tmp_path, stopTime=2.0)
    runs = tmp_path / "runs"
    proc = spawn("run", str(cfg), "--runs-dir", str(runs), "--no-progress", where)
    try:
        wait_for(lambda: any(_steps_on_disk(d) >= 5 for d in runs.glob("*")), 30, "the run's first rows")
        run_dir = next(runs.iterdir())
        shutil.rmtree(run_dir)
        out, err = proc.communicate(timeout=60)
    finally:
        reap(proc)
    assert proc.returncode == 3, err
    assert f"error: the run ended, but its results cannot be read: {run_dir}" in " ".join(err.split())
    assert "moved or removed while the run wrote it" in " ".join(err.split())
    assert "Traceback" not in err and "│" not in err


_SLOW_TO_LEAVE = """
import time

from hycosim.node.reference.gain import Gain


class SlowToLeave(Gain):
    def teardown(self):
        time.sleep(60)  # past the launcher's grace after a completed run
"""


def test_a_node_slow_to_exit_after_a_completed_run_is_a_warning_not_a_failure(tmp_path):
    (tmp_path / "slow.py").write_text(_SLOW_TO_LEAVE)
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "lazy", "UID": 2, "model": "slow.py:SlowToLeave", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "lazy.u"}], cosim={"stepSize": 0.01, "stopTime": 0.2})
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress", timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "warning: node 'lazy' had not exited" in res.stderr and "records are complete" in res.stderr, res.stderr
    run = next((tmp_path / "runs").iterdir())
    assert meta(run)["status"] == "completed" and len(read_rows(run)) == 21
