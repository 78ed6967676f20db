"""Deployment: the compose services as local processes, remote attach across network namespaces
with link cuts, and authenticated attach with access control."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
import zenoh
from hypothesis import given, settings
from hypothesis import strategies as st

from hycosim.scenario.scene_fmus import build_scene_fmus
from hycosim.core import frames
from hycosim.transport.keys import ProjectKeys
from hycosim.transport.security import SecurityError, read_credentials
from hycosim.transport.session import ConnectError, client_config, open_session, router_config
from tests.helpers import REPO, env, free_endpoint, hycosim, meta, read_rows, reap, spawn, wait_for, write_project
from tests.netns import hosts, netns_available

COMPOSE = REPO / "docker" / "docker-compose.yml"


def test_compose_file_is_valid_against_the_compose_schema():
    res = subprocess.run([sys.executable, "-m", "check_jsonschema", "--builtin-schema", "vendor.compose-spec",
                          str(COMPOSE)], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    spec = yaml.safe_load(COMPOSE.read_text())
    assert set(spec["services"]) == {"server", "rod", "robot", "policy", "camera"}
    grasp = json.loads((REPO / "hycosim" / "scenario" / "configs" / "grasp-paper.json").read_text())
    assert {n["nodeName"] for n in grasp["nodeLists"]} == set(spec["services"]) - {"server"}
    assert all("/config/grasp-paper.json" in s["command"] for s in spec["services"].values())
    # The image builds the FMUs where the config names them from /config.
    assert "hycosim scene fmus -o /build/fmus" in (REPO / "docker" / "Dockerfile").read_text()
    assert {n["fmu"] for n in grasp["nodeLists"] if "fmu" in n} == {"../build/fmus/Rod.fmu",
                                                                     "../build/fmus/RobotScene6.fmu"}


def test_compose_services_run_together_as_local_processes(tmp_path):
    """No Docker engine here: run each service's exact command, with the compose network's
    names mapped onto loopback and the volumes onto folders (the image's FMUs built beside the
    config as the Dockerfile builds them), and check that together they grasp the rod."""
    spec = yaml.safe_load(COMPOSE.read_text())
    endpoint = free_endpoint()
    port = endpoint.rsplit(":", 1)[1]
    doc = json.loads((REPO / "hycosim" / "scenario" / "configs" / "grasp-paper.json").read_text())
    doc["coSimulation"]["stopTime"] = 1.5
    config_dir = tmp_path / "config"
    config_dir.mkdir()
    (config_dir / "grasp-paper.json").write_text(json.dumps(doc))
    build_scene_fmus(tmp_path / "build" / "fmus")

    def local(args: list[str]) -> list[str]:
        mapped = []
        for a in args:
            a = a.replace("/config/", f"{config_dir}/").replace("tcp/server:7447", endpoint)
            a = a.replace("tcp/0.0.0.0:7447", endpoint).replace("/runs", str(tmp_path / "runs"))
            mapped.append(a)
        return mapped

    procs = {}
    try:
        for name, service in spec["services"].items():
            procs[name] = subprocess.Popen([sys.executable, "-m", "hycosim", *local(service["command"])],
                                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env(), cwd=REPO)
        outs = {name: p.communicate(timeout=120) for name, p in procs.items()}
    finally:
        reap(*procs.values())
    assert all(p.returncode == 0 for p in procs.values()), {n: o[1][-500:] for n, o in outs.items()}
    run = next((tmp_path / "runs").iterdir())
    assert meta(run)["status"] == "completed" and len(read_rows(run)) == 151
    assert port in meta(run)["endpoint"]
    events = (run / "events.jsonl").read_text()
    assert '"to": "grasp"' in events  # the policy closed the gripper on the rod
    rows = read_rows(run)
    assert any(r["rod.meas_valid"] == "1" for r in rows)  # the camera measured the physical rod for the twin


def _chain(tmp_path: Path, grace: float, stop: float) -> Path:
    return write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}],
        cosim={"stepSize": 0.01, "stopTime": stop, "realTime": True, "linkGrace": grace, "stepTimeout": 20.0},
        name="remote")


def _sensed(tmp_path: Path, grace: float, stop: float) -> Path:
    return write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp_source", "async": True, "rate": 20.0,
         "parameters": {"b": 1.0}, "output": ["y"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u", "extrapolation": "hold"}],
        cosim={"stepSize": 0.01, "stopTime": stop, "realTime": True, "linkGrace": grace, "stepTimeout": 20.0},
        name="remote")


def _remote_run(tmp_path: Path, grace: float, stop: float, cut_after: float, cut_for: float, project=_chain):
    """Server and the nodes clock and g each in its own network namespace; cut clock's link for a while."""
    cfg = project(tmp_path, grace, stop)
    run_dir = tmp_path / "run"
    py = [sys.executable, "-m", "hycosim"]
    with hosts(["clock", "g"]) as h:
        server = subprocess.Popen(h.exec(h.server) + py + ["server", str(cfg), "--listen", "tcp/0.0.0.0:7447",
                                                            "--run-dir", str(run_dir)],
                                  stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env(), cwd=REPO)
        nodes = {n: subprocess.Popen(h.exec(h.clients[n]) + py + ["node", n, str(cfg), "--connect",
                                                                   f"tcp/{h.server_address[n]}:7447"],
                                     stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env(), cwd=REPO)
                 for n in ("clock", "g")}
        try:
            wait_for(lambda: (run_dir / "values.csv").exists() and len(read_rows(run_dir)) > cut_after * 100, 30,
                     "steps before the cut")
            h.cut("clock")
            time.sleep(cut_for)
            h.restore("clock")
            _, err = server.communicate(timeout=60)
            node_out = {n: p.communicate(timeout=30) for n, p in nodes.items()}
        finally:
            reap(server, *nodes.values())
    return server.returncode, err, {n: (p.returncode, node_out[n][1]) for n, p in nodes.items()}, run_dir


needs_netns = pytest.mark.skipif(not netns_available(), reason="needs root and ip netns")


@needs_netns
def test_cosimulation_across_namespaces_survives_a_short_link_cut(tmp_path):
    code, err, nodes, run_dir = _remote_run(tmp_path, grace=5.0, stop=4.0, cut_after=1.0, cut_for=2.0)
    assert code == 0, err
    assert all(c == 0 for c, _ in nodes.values()), nodes
    rows = read_rows(run_dir)
    assert [int(r["step"]) for r in rows] == list(range(401))  # no step lost
    assert all(rows[k]["g.y"] == rows[k - 1]["clock.y"] for k in range(1, len(rows)))
    m = meta(run_dir)
    assert m["status"] == "completed" and m["reattached"] == {"clock": 1}
    lateness = [float(r["lateness_s"]) for r in read_rows(run_dir, "timing.csv")]
    assert max(lateness) > 0.5  # the cut shows up as lateness, not as lost steps


@needs_netns
def test_link_cut_beyond_the_grace_stops_with_a_clear_message_and_results(tmp_path):
    code, err, nodes, run_dir = _remote_run(tmp_path, grace=1.0, stop=6.0, cut_after=1.0, cut_for=4.0)
    assert code == 3
    assert "node 'clock' was lost at step" in err and "did not come back within the link grace of 1 s" in err
    assert nodes["g"][0] == 5, nodes["g"][1][-1500:]  # told the run failed, and why
    assert "node 'g': the server stopped the run: node 'clock' was lost" in nodes["g"][1]
    assert nodes["clock"][0] == 3 and "did not come back within the link grace" in nodes["clock"][1]
    m = meta(run_dir)
    rows = read_rows(run_dir)
    assert m["status"] == "failed" and len(rows) == m["steps"] >= 100
    assert all(rows[k]["g.y"] == rows[k - 1]["clock.y"] for k in range(1, len(rows)))


@needs_netns
def test_an_asynchronous_source_rides_out_a_short_link_cut(tmp_path):
    """A remote sensor (a camera, a real robot) whose link drops for less than linkGrace keeps
    sampling and is held at the server meanwhile; its samples resume when the link is back."""
    # The source reconnects within half a second of the link coming back: the run outlasts that.
    code, err, nodes, run_dir = _remote_run(tmp_path, grace=6.0, stop=8.0, cut_after=1.0, cut_for=2.0,
                                            project=_sensed)
    assert code == 0, err
    assert all(c == 0 for c, _ in nodes.values()), nodes
    m = meta(run_dir)
    assert m["status"] == "completed" and m["reattached"] == {"clock": 1}
    rows = read_rows(run_dir)
    ages = [float(r["age_s:g.u"]) if r["age_s:g.u"] else None for r in read_rows(run_dir, "timing.csv")]
    assert len(rows) == len(ages) == 801
    # Held through the cut: the value used grows old (beyond the lease and then some) ...
    assert max(a for a in ages if a is not None) > 1.0
    # ... and is fresh again at the end: the sensor sampled on and its samples came through.
    assert ages[-1] is not None and ages[-1] < 0.2
    assert float(rows[-1]["g.u"]) > 7.5  # y = t, sampled after the link came back
    assert m["samples_received"]["clock"] >= 80


def _secure(tmp_path: Path) -> Path:
    (tmp_path / "creds.txt").write_text("server:srv-pw\nclock:clock-pw\ng:g-pw\nwatcher:w-pw\n")
    return write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.01, "stopTime": 15.0, "realTime": True,
                                                 "attachTimeout": 20.0},
        name="secure", security={"credentials": "creds.txt"})


def test_wrong_or_missing_credentials_cannot_attach_and_a_forged_frame_is_dropped(tmp_path):
    cfg = _secure(tmp_path)
    endpoint = json.loads(cfg.read_text())["serverIP"]
    run_dir = tmp_path / "run"
    (tmp_path / "wrong.txt").write_text("not-the-password")
    # The same project with a short attach timeout, so the refused node gives up quickly.
    quick = json.loads(cfg.read_text())
    quick["coSimulation"]["attachTimeout"] = 2.0
    (tmp_path / "quick.json").write_text(json.dumps(quick))
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = [spawn("node", n, str(cfg)) for n in ("clock", "g")]  # passwords from the credentials file
    try:
        wait_for(lambda: (run_dir / "values.csv").exists() and len(read_rows(run_dir)) > 30, 30, "30 steps")
        # Paced at real time for 15 s: long enough for all that follows on a loaded machine.
        status = hycosim("status", endpoint, "--project", "secure", "--user", "watcher", "--password-file",
                         str(_pw(tmp_path, "w-pw")))
        assert status.returncode == 0 and "attached 2/2" in status.stdout, status.stderr
        bad = hycosim("node", "clock", str(tmp_path / "quick.json"), "--password-file", str(tmp_path / "wrong.txt"),
                      timeout=90)
        assert bad.returncode == 3 and "cannot open Zenoh session" in bad.stderr and "user 'clock'" in bad.stderr
        with pytest.raises(Exception):
            zenoh.open(client_config(endpoint, timeout_s=2.0))  # no credentials at all
        # The right credentials for a node that is already attached: refused, the run unharmed.
        second = hycosim("node", "g", str(cfg), timeout=90)
        assert second.returncode == 3 and "node 'g' is already attached" in second.stderr, second.stderr
        keys = ProjectKeys("secure")
        # Authenticated as clock, try to write g's outputs: the router's access control drops it.
        with zenoh.open(client_config(endpoint, user="clock", password="clock-pw")) as forger:
            for _ in range(5):
                forger.put(keys.up("g"), frames.encode(frames.OUTPUTS, 2, 10**6, 0.0, [123.0]),
                           congestion_control=zenoh.CongestionControl.BLOCK)
        running = len(read_rows(run_dir))
        _, err = server.communicate(timeout=60)
        for p in nodes:
            assert p.wait(timeout=30) == 0
    finally:
        reap(server, *nodes)
    assert server.returncode == 0, err
    m = meta(run_dir)
    assert m["dropped_frames"] == {}  # never reached the server
    rows = read_rows(run_dir)
    assert running < len(rows)  # the forger wrote while the run was going on
    assert all(r["g.y"] != "123.0" for r in rows)
    assert all(rows[k]["g.y"] == rows[k - 1]["clock.y"] for k in range(1, len(rows)))


# Where Python's and Rust's ideas of a line and of white space differ (Zenoh reads the file in
# Rust): \x0b, \x0c, \x1c-\x1f and U+2028 end a line for str.splitlines; \x1c-\x1f are
# stripped by str.strip and kept by Rust's trim; \x85, \xa0 and U+3000 are white space to both.
_ODD = "\r\x0b\x0c\x1c\x1f\x85\xa0\u2028\u3000\t "
_PASSWORDS = st.text(st.sampled_from("ab:#" + _ODD), max_size=6)
_CREDENTIAL_LINES = st.one_of(
    st.tuples(st.sampled_from(["server", "clock", "g", " watcher ", "u\u00e9", "", "\x1fx"]), _PASSWORDS)
    .map(lambda up: f"{up[0]}:{up[1]}"),
    st.sampled_from(["", "   ", "# a comment", "#a:b", "no colon here", ":no user", "a:b:c", "\ufeffserver:s"]))
_CREDENTIAL_FILES = st.tuples(st.lists(_CREDENTIAL_LINES, max_size=4), st.sampled_from(["\n", "\r\n"]),
                              st.sampled_from(["utf-8", "utf-8", "latin-1"]))


def _credentials_file(path: Path, lines: list[str], end: str, encoding: str) -> Path:
    text = end.join(lines)
    # Latin-1 where it can say the text (else UTF-8): a file saved in another encoding.
    path.write_bytes(text.encode(encoding if all(ord(c) < 256 for c in text) else "utf-8"))
    return path


@given(_CREDENTIAL_FILES)
def test_a_credentials_file_is_read_as_users_and_passwords_or_refused_naming_the_file_and_line(tmp_path_factory,
                                                                                              doc):
    path = _credentials_file(tmp_path_factory.mktemp("c") / "creds.txt", *doc)
    try:
        users = read_credentials(path)
    except SecurityError as exc:
        assert str(exc).startswith(str(path)), exc
        return
    # Every user with its password as written on a line of its own, around its first colon.
    lines = path.read_bytes().decode().split("\n")  # read_text would turn each \r into a line end
    for user, password in users.items():
        assert user and password and ":" not in user
        assert user.strip(" \t\xa0") == user and password.strip(" \t\xa0") == password
        assert any(user in line.partition(":")[0] and password in line.partition(":")[2] for line in lines)


@settings(max_examples=12, deadline=None)
@given(_CREDENTIAL_FILES)
def test_a_credentials_file_is_read_as_zenoh_reads_it(tmp_path_factory, doc):
    """Zenoh is the judge: a file the reader takes opens the router and lets every user in with
    its password as read; a file the reader refuses, Zenoh refuses too, except for the two it
    reads otherwise than its author meant (a comment line, a byte-order mark), refused by name."""
    lines, end, encoding = doc
    path = _credentials_file(tmp_path_factory.mktemp("z") / "creds.txt", ["server:s", *lines], end, encoding)
    try:
        users = read_credentials(path)
    except SecurityError as exc:
        users, refused = None, str(exc)
    endpoint = free_endpoint()
    settings_ = {"transport/auth/usrpwd": {"user": "server", "password": "s", "dictionary_file": str(path)}}
    try:
        router = open_session(router_config(endpoint, security=settings_), endpoint)
    except ConnectError as exc:
        assert users is None, f"Zenoh refused what the reader took ({exc}): {users}"
        return
    try:
        if users is None:
            assert "no comments" in refused or "byte-order mark" in refused, refused
            return
        for user, password in users.items():
            open_session(client_config(endpoint, timeout_s=3.0, user=user, password=password), endpoint).close()
    finally:
        router.close()


def _pw(tmp_path: Path, password: str) -> Path:
    path = tmp_path / f"pw-{password}"
    path.write_text(password)
    return path


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


def _make_ca(folder: Path, name: str) -> None:
    """A CA and a server certificate for 127.0.0.1 signed by it, made as docs/deployment.md shows."""
    folder.mkdir()
    _openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out", "ca.pem", "-days", "30",
             "-subj", f"/CN={name}", cwd=folder)
    _openssl("req", "-newkey", "rsa:2048", "-nodes", "-keyout", "server.key", "-out", "server.csr",
             "-subj", "/CN=localhost", cwd=folder)
    (folder / "san.cnf").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    _openssl("x509", "-req", "-in", "server.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
             "-out", "server.pem", "-days", "30", "-extfile", "san.cnf", cwd=folder)


def test_nodes_attach_over_tls_only_to_a_server_their_ca_signed(tmp_path):
    _make_ca(tmp_path / "site", "hycosim site CA")
    _make_ca(tmp_path / "other", "some other CA")
    endpoint = free_endpoint().replace("tcp/", "tls/")
    tls = {"rootCa": "site/ca.pem", "certificate": "site/server.pem", "privateKey": "site/server.key"}
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.01, "stopTime": 4.0, "realTime": True,
                                                 "attachTimeout": 20.0},
        name="tls", security={"tls": tls})
    doc = json.loads(cfg.read_text())
    doc["serverIP"] = endpoint
    cfg.write_text(json.dumps(doc))
    # What a node's machine holds: the project with the CA only; here, a CA that did not sign.
    doc["security"]["tls"] = {"rootCa": "other/ca.pem"}
    (tmp_path / "impostor.json").write_text(json.dumps(doc))
    doc["coSimulation"]["attachTimeout"] = 2.0
    (tmp_path / "quick.json").write_text(json.dumps(doc))
    run_dir = tmp_path / "run"
    server = spawn("server", str(cfg), "--run-dir", str(run_dir))
    nodes = [spawn("node", n, str(cfg)) for n in ("clock", "g")]
    try:
        wait_for(lambda: (run_dir / "values.csv").exists() and len(read_rows(run_dir)) > 10, 30, "10 steps")
        status = hycosim("status", endpoint, "--project", "tls", "--tls-ca", str(tmp_path / "site" / "ca.pem"))
        assert status.returncode == 0 and "attached 2/2" in status.stdout, status.stderr
        no_ca = hycosim("status", endpoint, "--project", "tls")
        assert no_ca.returncode == 2 and "give --tls-ca" in no_ca.stderr
        wrong = hycosim("node", "g", str(tmp_path / "quick.json"), timeout=90)
        assert wrong.returncode == 3 and "cannot open Zenoh session on " + endpoint in wrong.stderr, wrong.stderr
        _, err = server.communicate(timeout=60)
        assert server.returncode == 0, err
        assert all(p.wait(timeout=30) == 0 for p in nodes)
    finally:
        reap(server, *nodes)
    rows = read_rows(run_dir)
    assert len(rows) == 401 and all(rows[k]["g.y"] == rows[k - 1]["clock.y"] for k in range(1, len(rows)))
    assert meta(run_dir)["endpoint"] == endpoint


def test_tls_settings_that_cannot_work_are_refused_naming_the_key_or_file(tmp_path):
    nodes = [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]}]
    cfg = write_project(tmp_path / "a.json", nodes, name="tls")
    doc = json.loads(cfg.read_text())
    doc["serverIP"] = doc["serverIP"].replace("tcp/", "tls/")
    cfg.write_text(json.dumps(doc))
    res = hycosim("validate", str(cfg))
    assert res.returncode == 2 and "serverIP" in res.stdout + res.stderr and "no security.tls" in res.stdout + res.stderr
    doc["serverIP"] = doc["serverIP"].replace("tls/", "tcp/")
    doc["security"] = {"tls": {"rootCa": "ca.pem", "certificate": "server.pem"}}
    cfg.write_text(json.dumps(doc))
    res = hycosim("validate", str(cfg))
    text = res.stdout + res.stderr
    assert res.returncode == 2 and "security.tls: TLS is configured but serverIP" in text
    assert "certificate and privateKey go together" in text
    # Valid, but the server's key file is missing: the server says which file.
    doc["serverIP"] = doc["serverIP"].replace("tcp/", "tls/")
    doc["security"]["tls"]["privateKey"] = "missing.key"
    (tmp_path / "server.pem").write_text("not a certificate")
    cfg.write_text(json.dumps(doc))
    res = hycosim("server", str(cfg), "--run-dir", str(tmp_path / "run"), timeout=60)
    assert res.returncode == 2 and "server.pem: the server certificate is not a PEM file" in res.stderr, res.stderr
    assert not (tmp_path / "run").exists()  # read before anything is written
    assert "Traceback" not in res.stderr
