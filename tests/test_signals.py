"""SIGTERM and SIGHUP are ways out like Ctrl-C for the server, a node, the launcher and every other
command, each with its own exit status; a node process that ends before the run starts is
reported at once by the launcher."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest
import zenoh

from hycosim.core import frames
from hycosim.transport.keys import SERVER_TOKEN, ProjectKeys
from hycosim.transport.session import open_session, router_config
from tests.helpers import (HYCOSIM, REPO, env, free_port, meta, pids, read_rows, reap, spawn, wait_for,
                           write_project)
from tests.test_faults import _pair as fault_pair


def _pair(tmp_path):
    # The two-node project of the fault tests, paced long enough to be stopped midway.
    return fault_pair(tmp_path, stopTime=20.0)


def _rows(run_dir) -> int:
    return len(read_rows(run_dir)) if (run_dir / "values.csv").exists() else 0


def _contiguous(run_dir) -> list[dict]:
    rows = read_rows(run_dir)
    assert [r["step"] for r in rows] == [str(i) for i in range(len(rows))]
    return rows


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_signalled_server_writes_every_row_says_who_stopped_it_and_its_nodes_leave(tmp_path, sig):
    cfg = _pair(tmp_path)
    run_dir = tmp_path / "run"
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = [spawn("node", n, str(cfg)) for n in ("clock", "g")]
    try:
        wait_for(lambda: _rows(run_dir) > 30, 30, "30 steps")
        server.send_signal(sig)
        _, err = server.communicate(timeout=30)
        assert server.returncode == 128 + sig, err
        assert f"stopped by {sig.name}" in err and "Traceback" not in err
        for node in nodes:  # told by the server's STOP, not left waiting for its timeout
            _, node_err = node.communicate(timeout=20)
            assert node.returncode == 5 and f"stopped by {sig.name}" in node_err
    finally:
        reap(server, *nodes)
    m = meta(run_dir)
    assert m["status"] == "interrupted" and m["reason"] == f"stopped by {sig.name}"
    assert m["stopped_by"]["signal"] == sig.name and m["finished_at"] > m["started_at"]
    rows = _contiguous(run_dir)
    assert len(rows) >= 30 and int(rows[-1]["step"]) >= m["stopped_by"]["step"] - 1


def _with_source(tmp_path, model: str, parameters: dict | None = None):
    """A real-time asynchronous source feeding a stepping node, with a link grace: the run
    would wait that long for a source whose token went without a word."""
    return write_project(tmp_path / "p.json", [
        {"nodeName": "sensor", "UID": 1, "model": model, "async": True, "rate": 20.0, "output": ["y"],
         "parameters": parameters or {}},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "sensor.y", "to": "g.u"}], cosim={"stepSize": 0.01, "stopTime": 20.0, "realTime": True,
                                                   "linkGrace": 15.0}, name="faults")


@pytest.mark.parametrize("stopped, other, said", [
    ("g", "clock", "node 'g' stopped by SIGTERM after step"),
    # A source has no END of its own, but one its supervisor stops says so (it had been named a
    # lost token, and with a link grace only after the grace).
    ("sensor", "g", "node 'sensor' (an asynchronous source) stopped by SIGTERM (the run at step "),
], ids=["a stepping node", "an asynchronous source"])
def test_a_node_sent_sigterm_leaves_and_the_server_names_it_at_once(tmp_path, stopped, other, said):
    cfg = _pair(tmp_path) if stopped == "g" else _with_source(tmp_path, "ramp_source")
    run_dir = tmp_path / "run"
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = {n: spawn("node", n, str(cfg)) for n in (stopped, other)}
    try:
        wait_for(lambda: _rows(run_dir) > 30, 30, "30 steps")
        nodes[stopped].send_signal(signal.SIGTERM)
        began = time.monotonic()
        _, node_err = nodes[stopped].communicate(timeout=20)
        assert nodes[stopped].returncode == 143 and f"node {stopped!r} stopped by SIGTERM" in node_err
        _, err = server.communicate(timeout=30)
        assert time.monotonic() - began < 10  # a source's link grace is 15 s
        assert server.returncode == 3
        assert said in err and "liveliness" not in err
        assert nodes[other].wait(timeout=20) == 5
    finally:
        reap(server, *nodes.values())
    assert said in meta(run_dir)["reason"]
    _contiguous(run_dir)


def test_an_asynchronous_source_whose_model_fails_is_named_with_its_error_at_once(tmp_path):
    cfg = _with_source(tmp_path, "tests.nodes:FailingSource", {"fail_at": 1.0})
    run_dir = tmp_path / "run"
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = {n: spawn("node", n, str(cfg)) for n in ("sensor", "g")}
    try:
        _, node_err = nodes["sensor"].communicate(timeout=60)
        failed = time.monotonic()
        assert nodes["sensor"].returncode == 3, node_err
        said = "node 'sensor' (an asynchronous source): its model failed at t="
        assert said in node_err and "OSError: the sensor stopped answering" in node_err
        _, err = server.communicate(timeout=30)
        assert time.monotonic() - failed < 10  # not after the link grace of 15 s
        assert server.returncode == 3 and said in err and "(the run at step " in err and "liveliness" not in err, err
        assert nodes["g"].wait(timeout=20) == 5
    finally:
        reap(server, *nodes.values())
    rows = _contiguous(run_dir)
    # The samples the source took before it failed reached g: the run's records keep them.
    assert 0.5 < float(rows[-1]["t"]) < 3.0 and float(rows[-1]["g.u"]) > 0.5
    assert said in meta(run_dir)["reason"]


@pytest.mark.parametrize("answered", [True, False], ids=["the server answers", "no answer"])
def test_a_node_stopped_by_sigterm_holds_its_token_until_the_server_has_read_its_end(tmp_path, answered):
    """The END of a node a supervisor stops and the going of its token race to the server: in
    one loaded make test the token won and the server named a lost token. The node waits for
    the STOP that says the END was read (a bounded wait: without an answer it leaves all the
    same). The test plays the server, on a real router."""
    cfg = _pair(tmp_path)
    endpoint = json.loads(cfg.read_text())["serverIP"]
    keys = ProjectKeys("faults")
    with open_session(router_config(endpoint), endpoint) as router:
        up = router.declare_subscriber(keys.up("g"), zenoh.handlers.FifoChannel(64))
        server_token = router.liveliness().declare_token(keys.alive(SERVER_TOKEN))

        def g_holds_its_token() -> bool:
            return any(r.ok is not None for r in router.liveliness().get(keys.alive("g"), timeout=1.0))

        def next_from_g(kind: int) -> frames.Frame:
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                sample = up.try_recv()
                if sample is None:
                    time.sleep(0.01)
                    continue
                frame = frames.decode(sample.payload.to_bytes())
                if frame.kind == kind:
                    return frame
            raise AssertionError(f"no {frames.KIND_NAMES[kind]} from node g within 30 s")

        node = spawn("node", "g", str(cfg))
        try:
            wait_for(g_holds_its_token, 30, "node g's token")
            router.put(keys.down, frames.encode(frames.START, "run", 0.0, 0.01, time.time(), None, {"checkpoint": False}))
            assert next_from_g(frames.OUTPUTS).step == 0
            router.put(keys.down, frames.encode(frames.STEP, 0, 0.0, 0.01, "free", {"g": [1.5]}, [], {}))
            assert next_from_g(frames.OUTPUTS).step == 1
            node.send_signal(signal.SIGTERM)
            end = next_from_g(frames.END)
            assert end.clean is False and "node 'g' stopped by SIGTERM after step 1" in end.message
            time.sleep(0.5)
            assert g_holds_its_token() and node.poll() is None  # waiting for the server's word
            if answered:
                router.put(keys.down, frames.encode(frames.STOP, 1, end.message))
            _, err = node.communicate(timeout=20)
            assert node.returncode == 143 and "node 'g' stopped by SIGTERM" in err
            wait_for(lambda: not g_holds_its_token(), 10, "node g's token to go")
        finally:
            reap(node)
            server_token.undeclare()
            up.undeclare()


_HELD = """
import os, signal, sys, threading, time
from hycosim.core import signals
signals.raise_on_stop()
go = threading.Event()
def helper():  # started before the hold: stop signals unblocked here, as in Zenoh's threads
    go.wait()
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(10)
threading.Thread(target=helper, daemon=True).start()
counted = 0
try:
    signals.hold_stops()
    try:
        if sys.argv[1] == "thread":
            go.set()  # the kernel gives the signal to the helper, which does not block it
        else:
            os.kill(os.getpid(), signal.SIGTERM)
        began = time.monotonic()
        while time.monotonic() - began < 0.2:  # bytecodes at which an unheld signal would have been raised
            pass
        counted = 1
    finally:
        signals.release_stops()
    print("not stopped")
except signals.Stopped as exc:
    print(f"stopped by {signals.name_of(exc)} with counted={counted}")
"""


_SEND_OUTPUTS = """
import os, signal, sys, time, types
from hycosim.core import signals
from hycosim.node.sending import Outbox
signals.raise_on_stop()
def send(payload):  # the signal comes while the frame is sent, before the step is counted
    os.kill(os.getpid(), signal.SIGTERM)
    began = time.monotonic()
    while time.monotonic() - began < 0.2:
        pass
outbox = types.SimpleNamespace(receiver=types.SimpleNamespace(link=types.SimpleNamespace(send=send)), steps=6)
try:
    Outbox.send_outputs(outbox, b"frame", 7)
    print("not stopped")
except signals.Stopped as exc:
    print(f"stopped by {signals.name_of(exc)} with steps={outbox.steps} depth={signals.HELD.depth}")
"""


def test_send_outputs_holds_a_stop_until_the_step_is_counted():
    """The node's send of its outputs at every step, which holds stops itself (not through
    hold_stops): a SIGTERM during the send is raised once the step is counted, and nothing
    is left held."""
    done = subprocess.run([sys.executable, "-c", _SEND_OUTPUTS], capture_output=True, text=True, env=env(),
                          timeout=60)
    assert done.stdout.strip() == "stopped by SIGTERM with steps=7 depth=0", done.stdout + done.stderr


@pytest.mark.parametrize("threads", ["main", "thread"])
def test_a_stop_that_comes_between_sending_outputs_and_counting_them_waits_for_the_count(threads):
    """A node sends its outputs and counts the step with stop signals held: its END names the
    step the server has, wherever the SIGTERM falls, and whichever thread the kernel gives it
    to (with another thread that does not block it, the main thread's mask alone let the
    handler run inside the hold)."""
    done = subprocess.run([sys.executable, "-c", _HELD, threads], capture_output=True, text=True, env=env(),
                          timeout=60)
    assert done.stdout.strip() == "stopped by SIGTERM with counted=1", done.stdout + done.stderr


def test_the_launcher_sent_sigterm_stops_the_run_and_keeps_its_records(tmp_path):
    cfg = _pair(tmp_path)
    runs = tmp_path / "runs"
    proc = subprocess.Popen([*HYCOSIM, "run", str(cfg), "--runs-dir", str(runs), "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env(), cwd=REPO)
    try:
        wait_for(lambda: runs.exists() and any(_rows(d) > 30 for d in runs.iterdir()), 60, "30 steps")
        proc.send_signal(signal.SIGTERM)
        stopped = time.monotonic()
        _, err = proc.communicate(timeout=60)
        assert time.monotonic() - stopped < 20
    finally:
        reap(proc)
    assert proc.returncode == 143 and "stopped by SIGTERM" in err, err
    run_dir = next(runs.iterdir())
    m = meta(run_dir)
    assert m["status"] == "interrupted" and m["reason"] == "stopped by SIGTERM"
    assert len(_contiguous(run_dir)) > 30


def test_a_launchers_server_stopped_alone_before_the_run_starts_records_an_interrupted_run(tmp_path):
    """The server alone is stopped (a Dask worker stops a trial's server so) while a slow node
    still loads: the attached node leaves on the server's STOP before the launcher has seen the
    run start, and is not taken for a failed node: the run is interrupted, not failed."""
    cfg = _pair(tmp_path)
    doc = json.loads(cfg.read_text())
    doc["nodeLists"].append({"nodeName": "late", "UID": 3, "model": "tests.nodes:SlowStart",
                             "parameters": {"setup_s": 30.0}, "input": [], "output": ["y"]})
    doc["nodeNum"] = len(doc["nodeLists"])
    cfg.write_text(json.dumps(doc))
    runs = tmp_path / "runs"
    proc = spawn("run", str(cfg), "--runs-dir", str(runs), "--no-progress")
    try:
        log = lambda: next(runs.iterdir()) / "node-g.log.jsonl"  # noqa: E731
        wait_for(lambda: runs.exists() and any(runs.iterdir()) and log().exists()
                 and "server seen" in log().read_text(), 60, "node g attached")
        server = pids(f"hycosim server {cfg}")
        assert len(server) == 1
        os.kill(server[0], signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        reap(proc)
    run_dir = next(runs.iterdir())
    assert proc.returncode == 130, err
    assert "interrupted by Ctrl-C" in err and "node 'g'" not in err, err
    m = meta(run_dir)
    assert m["status"] == "interrupted" and m["reason"] == "interrupted by Ctrl-C", m
    # g left by the server's word, not by a signal of its own
    assert "the server stopped the run: interrupted by Ctrl-C" in (run_dir / "node-g.stderr.txt").read_text()


_SELF_ENDING = '''
import os, signal
from hycosim.node.interface import Node

class Quitter(Node):
    def setup(self, ctx):
        {action}
    def outputs(self):
        return {{"y": 0.0}}
    def step(self, t, h, inputs):
        pass
'''


@pytest.mark.parametrize("action, expected", [
    ("os.kill(os.getpid(), signal.SIGKILL)", "its process died of SIGKILL before the run started"),
    ("os._exit(0)", "its process ended before the run started with exit status 0"),
    ("raise SystemExit(7)", "exit status 7 before the run started"),
])
def test_a_node_process_that_ends_before_it_attaches_is_reported_at_once(tmp_path, action, expected):
    (tmp_path / "quitter.py").write_text(_SELF_ENDING.format(action=action))
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "q", "UID": 2, "model": "quitter.py:Quitter", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "q.u"}], cosim={"stepSize": 0.01, "stopTime": 1.0, "attachTimeout": 60.0})
    started = time.monotonic()
    res = subprocess.run([*HYCOSIM, "run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress"],
                         capture_output=True, text=True, env=env(), cwd=REPO, timeout=120)
    assert time.monotonic() - started < 30  # not the attachTimeout of 60 s
    assert res.returncode == 3, res.stderr
    assert f"q: {expected}" in res.stderr
    run = next((tmp_path / "runs").iterdir())
    m = meta(run)  # the run directory says what the user was told
    assert m["status"] == "failed" and expected in m["reason"]
    # Started again once (the default --restarts is 3); it failed alike, so not a third time.
    said = (run / "node-q.stderr.txt").read_text()
    assert "started again (1 of 3)" in said and "(2 of 3)" not in said and "(after 1 restart(s))" in res.stderr


def _dashboard(tmp_path) -> list[str]:
    # A dashboard of a server that is not there: it serves its page and keeps retrying.
    return ["dashboard", f"tcp/127.0.0.1:{free_port()}", "--port", "0", "--retry", "5"]


def _controller(tmp_path) -> list[str]:
    from hycosim.scenario.krl.eki import EkiConfig

    eki = tmp_path / "eki.xml"
    eki.write_text(EkiConfig().to_xml())
    return ["krl", "controller", "--eki", str(eki), "--port", str(free_port())]


@pytest.mark.parametrize("command, ready", [(_dashboard, "dashboard: http://"),
                                            (_controller, "emulated KUKA controller listening")],
                         ids=["dashboard", "krl controller"])
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_every_command_a_signal_stops_exits_with_that_signals_status(tmp_path, command, ready, sig):
    """Not only the server, the nodes and the launcher: a dashboard or an emulated controller
    that a supervisor stops says which signal did it (Typer alone gave 130 for all three)."""
    proc = spawn(*command(tmp_path))
    try:
        line = proc.stdout.readline()  # the command's first word: it is serving
        assert ready in line, (line, proc.stderr.read() if proc.poll() is not None else "")
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == 128 + sig, err
        assert "Traceback" not in err, err
    finally:
        reap(proc)


# Runs the console entry point with a Ctrl-C that comes exactly as a module is first imported:
# while the command line itself is imported, or while an extension initialises, which turns the
# interrupt into an ImportError of its own (MuJoCo's said "initialization failed" when Ctrl-C
# came as `hycosim train` started).
_INTERRUPTED_IMPORT = '''
import os, signal, sys, time
from importlib.abc import MetaPathFinder

# Ctrl-C as at a terminal: Python's own handler, whatever the suite was started with (a shell
# without job control starts a background job, and so this suite, with SIGINT ignored, which
# Python then keeps: the interrupt never came, and the command ran to exit 0).
signal.signal(signal.SIGINT, signal.default_int_handler)

class At(MetaPathFinder):
    def __init__(self, module, as_import_error):
        self.module, self.as_import_error = module, as_import_error
    def find_spec(self, name, path, target=None):
        if name != self.module:
            return None
        sys.meta_path.remove(self)
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5)
        except KeyboardInterrupt:
            if self.as_import_error:
                raise ImportError("initialization failed") from None
            raise
        return None

module, how = sys.argv[1], sys.argv[2]
sys.argv = ["hycosim", *sys.argv[3:]]
sys.meta_path.insert(0, At(module, how == "import-error"))
from hycosim.__main__ import main
main()
'''


@pytest.mark.parametrize("module, how, command", [
    ("typer", "interrupt", ["--help"]),  # the command line's own imports
    ("mujoco", "import-error", ["train", "-o", "{tmp}/t", "--demos", "1"]),
], ids=["during the command line's imports", "as an extension initialises"])
def test_ctrl_c_as_a_command_starts_exits_130_without_a_traceback(tmp_path, module, how, command):
    res = subprocess.run([sys.executable, "-c", _INTERRUPTED_IMPORT, module, how,
                          *(c.format(tmp=tmp_path) for c in command)],
                         capture_output=True, text=True, env=env(), cwd=REPO, timeout=120)
    assert res.returncode == 130, res.stderr
    assert "interrupted by Ctrl-C" in res.stderr and "Traceback" not in res.stderr, res.stderr
