"""A node on its server's host reaches it over a Unix socket beside the TCP port where it
waits by blocking (coSimulation.localSocket): the same run, the same values, the same refusals."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import socket
import tempfile
import time
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hycosim.transport.session import local_socket, private_folder, reach, server_socket, sweep_sockets
from tests.helpers import free_port, hycosim, meta, read_rows, reap, run_project, spawn, wait_for, write_project

NOBODY = 65534


@pytest.fixture
def sockets(monkeypatch: pytest.MonkeyPatch) -> Path:
    """A folder of this test's for the servers' sockets (HYCOSIM_SOCKETS), which the processes it
    starts inherit; short, as a socket's path must be (pytest's own folders may be too deep)."""
    folder = Path(tempfile.mkdtemp(prefix="hs-", dir="/tmp"))
    monkeypatch.setenv("HYCOSIM_SOCKETS", str(folder))
    yield folder
    for below in folder.rglob("*"):
        if below.is_dir():
            below.chmod(0o700)  # a folder a test handed to another user: still root's to remove
    shutil.rmtree(folder, ignore_errors=True)


def test_only_a_tcp_endpoint_on_a_loopback_address_has_a_socket_beside_it(sockets):
    netns = os.stat("/proc/self/ns/net").st_ino
    mine = sockets / f"hycosim-{os.getuid()}"
    assert local_socket("tcp/127.0.0.1:7447") == mine / f"{netns}-7447.sock"
    assert local_socket("tcp/127.0.0.9:7") == mine / f"{netns}-7.sock"
    assert local_socket("tcp/[::1]:7448") == mine / f"{netns}-7448.sock"
    assert local_socket("tcp/localhost:7449") == mine / f"{netns}-7449.sock"
    for other in ("tcp/10.0.0.1:7447", "tcp/[fe80::1]:7447", "tls/127.0.0.1:7447", "udp/127.0.0.1:7447",
                  "tcp/server:7447", "tcp/127.0.0.1", "tcp/127.0.0.1:http", "127.0.0.1:7447", ""):
        assert local_socket(other) is None, other


_HOSTS = st.sampled_from(["127.0.0.1", "127.255.0.9", "[::1]", "::1", "localhost", "10.0.0.1", "[fe80::1]",
                          "127.1", "0.0.0.0", "", "[]", "[127.0.0.1]", "x"]) | st.text(max_size=20)
_PORTS = st.integers(-5, 70_000).map(str) | st.sampled_from(["", "٣", "7 ", "+1", "0x1f"]) | st.text(max_size=6)
_ENDPOINTS = st.text(max_size=60) | st.builds("{}/{}:{}".format, st.sampled_from(["tcp", "tls", "udp", "TCP", ""]),
                                              _HOSTS, _PORTS)


@given(_ENDPOINTS)
def test_any_endpoint_text_has_no_socket_or_one_in_the_users_folder(endpoint):
    got = local_socket(endpoint)
    if got is None:
        return
    kind, _, address = endpoint.partition("/")
    port = address.rpartition(":")[2]
    assert kind == "tcp" and port.isascii() and port.isdigit()
    assert got.parent.name == f"hycosim-{os.getuid()}" and got.name.endswith(f"-{port}.sock")
    assert len(os.fsencode(got)) <= 107


def test_a_socket_folder_is_used_only_when_it_is_this_users_alone(tmp_path):
    fresh = tmp_path / "fresh"
    assert private_folder(fresh) and fresh.stat().st_mode & 0o777 == 0o700
    shared = tmp_path / "shared"
    shared.mkdir(mode=0o755)
    shared.chmod(0o755)
    assert not private_folder(shared)
    theirs = tmp_path / "theirs"
    theirs.mkdir(mode=0o700)
    os.chown(theirs, NOBODY, NOBODY)
    assert not private_folder(theirs)
    (tmp_path / "a-file").write_text("")
    assert not private_folder(tmp_path / "a-file")
    assert not private_folder(tmp_path / "missing" / "below")


def _unix_listener(path: Path) -> socket.socket:
    path.parent.mkdir(parents=True, exist_ok=True)
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.bind(str(path))
    s.listen(4)
    return s


def test_a_node_takes_the_socket_where_it_listens_and_tcp_where_only_tcp_does(sockets):
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    local = local_socket(endpoint)
    t0 = time.monotonic()
    assert reach(endpoint, 0.3) == endpoint  # nothing up: TCP, for Zenoh to report
    assert time.monotonic() - t0 < 2.0
    with socket.create_server(("127.0.0.1", port)):
        assert reach(endpoint, 5.0) == endpoint  # a server on TCP alone
        with _unix_listener(local):
            assert reach(endpoint, 5.0) == f"unixsock-stream/{local}"
    # What a killed server leaves: its socket's file, which nobody answers at any more.
    assert local.exists()
    with socket.create_server(("127.0.0.1", port)):
        assert reach(endpoint, 5.0) == endpoint


def _ring(tmp_path: Path, n: int, **cosim) -> Path:
    nodes = [{"nodeName": f"n{i}", "UID": i + 1, "model": "gain", "parameters": {"k": 0.5, "b": 1.0},
              "input": ["u"], "output": ["y"]} for i in range(n)]
    links = [{"from": f"n{i}.y", "to": f"n{(i + 1) % n}.u"} for i in range(n)]
    return write_project(tmp_path / "ring.json", nodes, links, name="ring",
                         cosim={"stepSize": 0.1, "stopTime": 30.0, "waitStrategy": "block", **cosim})


def _over(run_dir: Path) -> dict[str, str]:
    """How each node attached, from its log: ``unix`` (its server's socket under the test's
    folder), ``tcp`` (loopback) or the endpoint as logged."""
    over = {}
    for log in run_dir.glob("node-*.log.jsonl"):
        for line in log.read_text().splitlines():
            entry = json.loads(line)
            if entry.get("event") == "attached":
                where = entry["over"]
                unix = where.startswith(f"unixsock-stream/{os.environ['HYCOSIM_SOCKETS']}/hycosim-{os.getuid()}/")
                over[entry["node"]] = ("unix" if unix and where.endswith(".sock") else
                                       "tcp" if where.startswith("tcp/127.0.0.1:") else where)
    return over


def test_a_run_over_the_socket_records_what_the_same_run_over_tcp_does(tmp_path, sockets):
    cfg = _ring(tmp_path, 3)
    doc = json.loads(cfg.read_text())
    unix = run_project(cfg, tmp_path / "unix")
    assert _over(unix) == {"n0": "unix", "n1": "unix", "n2": "unix"}
    assert not list(sockets.rglob("*.sock"))  # the server's socket goes with it
    doc["coSimulation"]["localSocket"] = False
    (tmp_path / "tcp.json").write_text(json.dumps(doc))
    tcp = run_project(tmp_path / "tcp.json", tmp_path / "tcp")
    assert _over(tcp) == {"n0": "tcp", "n1": "tcp", "n2": "tcp"}
    assert meta(unix)["status"] == meta(tcp)["status"] == "completed"
    assert (unix / "values.csv").read_bytes() == (tcp / "values.csv").read_bytes()
    assert len(read_rows(unix)) == 301
    # Where nodes poll, TCP (Zenoh's socket reader hands a frame over in two wake-ups).
    doc["coSimulation"]["localSocket"], doc["coSimulation"]["waitStrategy"] = True, "yield"
    (tmp_path / "polls.json").write_text(json.dumps(doc))
    assert set(_over(run_project(tmp_path / "polls.json", tmp_path / "polls")).values()) == {"tcp"}


def test_a_server_whose_socket_folder_is_not_its_own_serves_its_nodes_over_tcp(tmp_path, sockets):
    theirs = sockets / f"hycosim-{os.getuid()}"
    theirs.mkdir(mode=0o700)
    os.chown(theirs, NOBODY, NOBODY)
    cfg = _ring(tmp_path, 2)
    run_dir = run_project(cfg, tmp_path / "runs")
    assert _over(run_dir) == {"n0": "tcp", "n1": "tcp"}
    assert meta(run_dir)["status"] == "completed" and len(read_rows(run_dir)) == 301
    server_log = (run_dir / "server.log.jsonl").read_text()
    assert "no Unix socket for nodes on this host" in server_log and str(theirs) in server_log


def test_credentials_are_asked_over_the_socket_as_over_tcp(tmp_path, sockets):
    (tmp_path / "creds.txt").write_text("server:srv-pw\nclock:clock-pw\ng:g-pw\n")
    (tmp_path / "wrong.txt").write_text("not-the-password")
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.1, "stopTime": 5.0, "waitStrategy": "block",
                                                 "attachTimeout": 20.0},
        name="secure", security={"credentials": "creds.txt"})
    run_dir = run_project(cfg, tmp_path / "runs")
    assert _over(run_dir) == {"clock": "unix", "g": "unix"}
    rows = read_rows(run_dir)
    assert len(rows) == 51 and all(rows[k]["g.y"] == rows[k - 1]["clock.y"] for k in range(1, len(rows)))
    # A wrong password over the socket: refused, as over TCP, naming the user (the node's own
    # attach timeout short, so that it gives up quickly; the server's the project's).
    quick = json.loads(cfg.read_text())
    quick["coSimulation"]["attachTimeout"] = 2.0
    (tmp_path / "quick.json").write_text(json.dumps(quick))
    local = local_socket(quick["serverIP"])
    server = spawn("server", str(cfg), "--run-dir", str(tmp_path / "refused"))
    try:
        wait_for(lambda: _accepts(local), 20, "the server's socket")
        bad = hycosim("node", "clock", str(tmp_path / "quick.json"), "--password-file", str(tmp_path / "wrong.txt"),
                      timeout=90)
        assert bad.returncode == 3 and "cannot open Zenoh session" in bad.stderr and "user 'clock'" in bad.stderr
    finally:
        reap(server)


def _accepts(path: Path) -> bool:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        try:
            probe.connect(str(path))
        except OSError:
            return False
    return True


def test_a_socket_the_server_cannot_listen_on_leaves_its_nodes_tcp(tmp_path, sockets):
    cfg = _ring(tmp_path, 2)
    endpoint = json.loads(cfg.read_text())["serverIP"]
    local = local_socket(endpoint)
    local.mkdir(parents=True)  # a folder where the socket would be
    local.parent.chmod(0o700)
    run_dir = tmp_path / "run"
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = [spawn("node", n, str(cfg)) for n in ("n0", "n1")]
    try:
        _, err = server.communicate(timeout=60)
        said = [p.communicate(timeout=30)[1] for p in nodes]
    finally:
        reap(server, *nodes)
    assert server.returncode == 0, err
    assert [p.returncode for p in nodes] == [0, 0], said
    assert meta(run_dir)["status"] == "completed" and len(read_rows(run_dir)) == 301
    assert "no Unix socket for nodes on this host" in (run_dir / "server.log.jsonl").read_text()
    for text in said:
        attached = [line for line in text.splitlines() if "attached" in line]
        assert attached and endpoint in attached[0] and "unixsock" not in attached[0], text


def test_a_socket_path_too_long_to_listen_on_is_none(monkeypatch, tmp_path):
    monkeypatch.setenv("HYCOSIM_SOCKETS", str(tmp_path / ("x" * 90)))
    assert local_socket("tcp/127.0.0.1:7447") is None


def test_a_server_sweeps_the_sockets_killed_servers_left_and_keeps_the_live_ones(tmp_path, sockets):
    folder = sockets / f"hycosim-{os.getuid()}"
    assert private_folder(folder)
    stale = folder / "1-1111.sock"
    _unix_listener(stale).close()  # a killed server's: its file stays, nobody listens
    (folder / "1-1111.sock.lock").write_text("")
    live = folder / "1-2222.sock"
    listener = _unix_listener(live)
    (folder / "1-2222.sock.lock").write_text("")
    holder = os.open(folder / "1-2222.sock.lock", os.O_RDWR)
    fcntl.flock(holder, fcntl.LOCK_EX)  # as a listening router holds its lock
    try:
        assert sweep_sockets(folder) == 1
        assert sorted(p.name for p in folder.iterdir()) == ["1-2222.sock", "1-2222.sock.lock"]
        # A server's start sweeps its folder: what a killed one left goes, its own socket comes.
        _unix_listener(stale).close()
        (folder / "1-1111.sock.lock").write_text("")
        run_project(_ring(tmp_path, 2), tmp_path / "runs")
        assert sorted(p.name for p in folder.iterdir()) == ["1-2222.sock", "1-2222.sock.lock"]
    finally:
        os.close(holder)
        listener.close()


def test_a_relative_socket_folder_gives_no_socket_and_such_an_endpoint_is_reached_as_it_is(monkeypatch):
    monkeypatch.setenv("HYCOSIM_SOCKETS", "relative/folder")  # the server's and a node's may differ
    assert local_socket("tcp/127.0.0.1:7447") is None
    t0 = time.monotonic()
    assert reach("tcp/127.0.0.1:7447", 30.0) == "tcp/127.0.0.1:7447"  # no probe where no socket can be
    assert reach("tcp/10.0.0.1:7447", 30.0) == "tcp/10.0.0.1:7447"
    assert time.monotonic() - t0 < 1.0


def test_a_server_takes_a_socket_only_in_a_folder_of_its_users_alone(sockets):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    assert server_socket("tcp/10.0.0.1:7447") == (None, None)
    local, why_not = server_socket(endpoint)
    assert local == local_socket(endpoint) and why_not is None
    assert local.parent.stat().st_mode & 0o777 == 0o700
    os.chown(local.parent, NOBODY, NOBODY)
    local, why_not = server_socket(endpoint)
    assert local is None and str(sockets) in why_not and "not this user's alone" in why_not
