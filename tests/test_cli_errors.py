"""Bad arguments to the tool commands: a message naming the file or option, exit 2, no traceback."""

from __future__ import annotations

import json

import pytest

from tests.helpers import REPO, hycosim

GRASP = str(REPO / "hycosim" / "scenario" / "configs" / "grasp.json")


@pytest.mark.parametrize("args, message", [
    (["camera", "--fps", "0"], "'--fps'"),
    (["camera", "--seconds", "-1"], "'--seconds'"),
    (["camera", "--seconds", "0.1", "--annotate", "{missing}/a.mp4"], "{missing}/a.mp4: cannot write a video there"),
    (["camera", "--seconds", "0.1", "--annotate", "{tmp}/a.gif"], "{tmp}/a.gif: cannot write a video there"),
    (["train", "--eval-every", "0", "-o", "{tmp}/train"], "'--eval-every'"),
    (["krl", "controller", "--eki", "{missing}/eki.xml"], "{missing}/eki.xml: cannot read"),
    (["scene", "fmus", "-o", "{file}/fmus"], "{file}/fmus: cannot write the FMUs there"),
    (["scene", "reach", GRASP, "-o", "{missing}/reach.png"], "{missing}/reach.png: No such file or directory"),
    # A negative timeout waited for good, nan ended in a traceback; without a bound nan and inf pass.
    (["status", "tcp/127.0.0.1:9", "--timeout", "-1"], "'--timeout'"),
    (["status", "tcp/127.0.0.1:9", "--timeout", "nan"], "'--timeout'"),
    (["camera", "--initial-angle", "nan"], "nan is not a finite number"),
    (["camera", "--fps", "inf"], "'--fps'"),
    (["krl", "controller", "--eki", "{missing}/eki.xml", "--angle", "inf"], "inf is not a finite number"),
    (["train", "--seed", "-5", "-o", "{tmp}/train"], "'--seed'"),  # numpy's error, not naming it, after setup
])
def test_bad_arguments_are_named(tmp_path, args, message):
    (tmp_path / "a-file").write_text("not a folder")
    where = {"tmp": tmp_path, "missing": tmp_path / "missing", "file": tmp_path / "a-file"}
    res = hycosim(*(a.format(**where) for a in args))
    assert res.returncode == 2, res.stderr
    assert message.format(**where) in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "train").exists() and not (tmp_path / "a.gif").exists()


def test_a_listen_port_already_taken_fails_once_and_quickly(tmp_path):
    """The server cannot listen: one message (not one per layer), the run directory named once,
    and the nodes, stuck connecting to whatever holds the port, are not waited for one by one."""
    import socket
    import time

    from tests.helpers import write_project

    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": f"n{i}", "UID": i + 1, "model": "gain", "input": ["u"], "output": ["y"]} for i in range(4)],
        cosim={"stepSize": 0.1, "stopTime": 1.0, "attachTimeout": 60.0})
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen()
        started = time.monotonic()
        res = hycosim("run", str(cfg), "--listen", f"tcp/127.0.0.1:{holder.getsockname()[1]}",
                      "--runs-dir", str(tmp_path / "runs"), "--no-progress")
        took = time.monotonic() - started
    assert res.returncode == 3 and "Address already in use" in res.stderr and "Traceback" not in res.stderr
    assert res.stderr.count("results so far:") == 1 and res.stderr.count("error:") == 1, res.stderr
    assert took < 40, f"{took:.0f} s"  # 2 s grace, then one 10 s bound for all four nodes


def test_logs_are_json_for_collectors_and_text_on_a_terminal(tmp_path):
    import json
    import os
    import pty
    import subprocess
    import sys

    from tests.helpers import env

    script = ("import structlog; from hycosim.core import logs; logs.configure(); "
              "structlog.get_logger('x').info('server seen', node='rod', step=3)")
    piped = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env(), timeout=60)
    record = json.loads(piped.stderr)
    assert record["event"] == "server seen" and record["node"] == "rod" and record["step"] == 3
    main, terminal = pty.openpty()
    try:
        proc = subprocess.run([sys.executable, "-c", script], stderr=terminal, env=env(), timeout=60)
        text = os.read(main, 4096).decode()
    finally:
        os.close(main)
        os.close(terminal)
    assert proc.returncode == 0 and "server seen" in text and "node" in text and "rod" in text
    assert not text.lstrip().startswith("{")
    (tmp_path / "x.log").write_text("")
    to_file = script.replace("logs.configure()", f"logs.configure({str(tmp_path / 'x.log')!r})")
    subprocess.run([sys.executable, "-c", to_file], env=env(), timeout=60, check=True)
    assert json.loads((tmp_path / "x.log").read_text())["step"] == 3  # a file is always JSON lines


def test_status_ignores_answers_that_are_not_a_hycosim_servers(tmp_path):
    """Anyone on the network may answer on the status key; a stranger's answer is no server."""
    import zenoh

    from hycosim.transport.keys import ProjectKeys
    from hycosim.transport.session import router_config
    from tests.helpers import free_endpoint

    endpoint = free_endpoint()
    strangers = [b"not json", b"[1, 2]", b'{"project": "x"}',
                 # every key of a server's answer, with values of the wrong types
                 b'{"project": "x", "step": 1, "t": 0, "mode": "free", "attached": 3, "expected": []}',
                 b'{"project": ["x"], "step": "1", "t": null, "mode": 1, "attached": [1], "expected": {}}',
                 b"[" * 5000]  # deeper than Python's JSON decoder recurses
    with zenoh.open(router_config(endpoint)) as session:
        # Each on its own key, as a server answers: answers on the query's (wildcard) key would
        # be consolidated into one, and the client would read only one of them.
        queryables = [session.declare_queryable(key := ProjectKeys(f"p{i}").status,
                                                lambda q, key=key, answer=answer: q.reply(key, answer))
                      for i, answer in enumerate(strangers)]
        res = hycosim("status", endpoint, "--timeout", "1", timeout=60)
        for q in queryables:
            q.undeclare()
    assert res.returncode == 3 and "Traceback" not in res.stderr
    assert f"no hycosim server answered on {endpoint}" in res.stderr


def test_credential_and_password_files_that_are_no_utf8_text_are_named(tmp_path):
    """A credentials or password file saved in another encoding (Latin-1 here) is named with where
    it stops being UTF-8. Before, both ended the command in a UnicodeDecodeError traceback."""
    from tests.helpers import write_project

    (tmp_path / "creds.txt").write_bytes("server:s\u00e9cret\nclock:c\n".encode("latin-1"))
    (tmp_path / "pw.txt").write_bytes("w\u00e9".encode("latin-1"))
    cfg = write_project(tmp_path / "p.json", [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]}],
                        name="secure", security={"credentials": "creds.txt"})
    server = hycosim("server", str(cfg), "--runs-dir", str(tmp_path / "runs"))
    run = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress")
    status = hycosim("status", "tcp/127.0.0.1:9", "--user", "watcher", "--password-file", str(tmp_path / "pw.txt"))
    creds = f"{tmp_path / 'creds.txt'}: cannot read credentials (not UTF-8 text at byte 8)"
    for res, says in ((server, creds), (run, creds),
                      (status, f"{tmp_path / 'pw.txt'}: cannot read the password (not UTF-8 text at byte 1)")):
        assert res.returncode == 2 and says in res.stderr and "Traceback" not in res.stderr, res.stderr
    # Bad input, read before anything is written: no run directory is left behind.
    assert not (tmp_path / "runs").exists()
    (tmp_path / "creds.txt").unlink()
    for args in (("server",), ("run", "--no-progress")):
        res = hycosim(*args, str(cfg), "--runs-dir", str(tmp_path / "runs"))
        assert res.returncode == 2 and f"{tmp_path / 'creds.txt'}" in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "runs").exists()
    # A password file Zenoh could not match against any dictionary line: empty, or two lines.
    for text, says in (("  \n", "holds no password"), ("pw\nmore\n", "holds more than one line")):
        (tmp_path / "pw.txt").write_text(text)
        res = hycosim("status", "tcp/127.0.0.1:9", "--user", "watcher", "--password-file", str(tmp_path / "pw.txt"))
        assert res.returncode == 2 and f"{tmp_path / 'pw.txt'}: {says}" in res.stderr, res.stderr


def test_an_output_folder_that_is_a_file_is_named_as_no_folder(tmp_path):
    from tests.helpers import write_project

    cfg = write_project(tmp_path / "p.json", [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
                                              {"nodeName": "b", "UID": 2, "input": ["u"], "output": ["y"]}],
                        [{"from": "clock.y", "to": "b.u"}])
    (tmp_path / "runs").write_text("a file")
    # Every folder a command writes into is made one way (run directories, FMUs, trials, exports).
    for args in (("server", str(cfg), "--runs-dir"), ("run", str(cfg), "--no-progress", "--runs-dir"),
                 ("server", str(cfg), "--run-dir"), ("fmu", "build", str(cfg), "-o"), ("scene", "fmus", "-o")):
        res = hycosim(*args, str(tmp_path / "runs"))
        assert res.returncode == 2, res.stderr
        assert f"{tmp_path / 'runs'}: " in res.stderr and "Traceback" not in res.stderr
        assert "exists and is not a folder" in res.stderr and "File exists" not in res.stderr
    assert (tmp_path / "runs").read_text() == "a file"


def test_help_shows_plain_metavars_and_whole_sentences():
    """Help as a user reads it: FILE, not {file}; no <bool> after a flag; each command's line in
    the list one whole summary (a docstring's line breaks fell mid-sentence there)."""
    import subprocess

    from tests.helpers import HYCOSIM, env

    def wide(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([*HYCOSIM, *args], capture_output=True, text=True, timeout=120,
                              env=dict(env(), COLUMNS="240"), cwd=REPO)

    res = wide("--help")
    assert res.returncode == 0 and "<bool>" not in res.stdout and "{" not in res.stdout, res.stdout
    listing = res.stdout.split("Commands", 1)[1]
    rows = [line.strip("│ ").strip() for line in listing.splitlines() if line.startswith("│")]
    assert len(rows) >= 15, rows
    assert all(row.endswith((".", ")")) for row in rows), [r for r in rows if not r.endswith((".", ")"))]
    res = wide("validate", "--help")
    assert "Usage: hycosim validate [OPTIONS] FILE" in res.stdout and "<bool>" not in res.stdout, res.stdout


def test_an_unknown_node_of_a_pairs_link_is_named_once(tmp_path):
    project = tmp_path / "p.json"
    project.write_text(json.dumps({
        "projectName": "p", "nodeNum": 1, "linkNum": 1,
        "nodeLists": [{"nodeName": "a", "UID": 1, "model": "gain", "input": ["u"], "output": ["y"]}],
        "linkLists": [{"from": "zz", "to": "a", "pairs": [["y", "u"], ["y", "u2"], ["y", "u3"]]}],
        "coSimulation": {"stepSize": 0.1, "stopTime": 1.0}}))
    res = hycosim("validate", str(project))
    assert res.returncode == 2 and res.stderr.count("unknown node 'zz'") == 1, res.stderr


def test_fmu_build_into_a_missing_tree_is_refused_and_makes_nothing(tmp_path):
    project = tmp_path / "p.json"
    project.write_text(json.dumps({
        "projectName": "p", "nodeNum": 1, "linkNum": 0,
        "nodeLists": [{"nodeName": "tool", "UID": 1, "input": ["u"], "output": ["y"]}],
        "linkLists": [], "coSimulation": {"stepSize": 0.1, "stopTime": 1.0}}))
    res = hycosim("fmu", "build", str(project), "-o", str(tmp_path / "no" / "such" / "dir"))
    assert res.returncode == 2 and "no/such: its parent folder" not in res.stderr
    assert f"its parent folder {tmp_path / 'no' / 'such'} does not exist" in res.stderr, res.stderr
    assert not (tmp_path / "no").exists()


def test_a_reader_that_stops_early_ends_the_command_quietly(tmp_path):
    """`hycosim report RUN | head -1`: exit 0, no traceback, when the pipe closes."""
    import subprocess
    import sys

    doc = {"projectName": "chain", "nodeNum": 2, "linkNum": 1,
           "nodeLists": [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
                         {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]}],
           "linkLists": [{"from": "clock.y", "to": "g.u"}], "coSimulation": {"stepSize": 0.01, "stopTime": 0.2}}
    (tmp_path / "p.json").write_text(json.dumps(doc))
    res = hycosim("run", str(tmp_path / "p.json"), "--in-process", "--no-progress", "--runs-dir", str(tmp_path / "runs"))
    assert res.returncode == 0, res.stderr
    run = next((tmp_path / "runs").iterdir())
    script = (f"set -o pipefail; {sys.executable} -m hycosim report {run} | head -c 1 >/dev/null; "
              f"echo status=$?")
    res = subprocess.run(["bash", "-c", script], capture_output=True, text=True, cwd=REPO, timeout=120,
                         env=dict(__import__("os").environ, PYTHONPATH=str(REPO), COLUMNS="60"))
    assert "status=0" in res.stdout and "Traceback" not in res.stderr and "BrokenPipe" not in res.stderr, (
        res.stdout, res.stderr)


def test_run_of_a_model_that_is_not_there_ends_at_once_with_2_and_makes_no_run_directory(tmp_path):
    import time

    for model, says in (("gian", "did you mean 'gain'?"), ("nowhere_module:Thing", "no module named 'nowhere_module'"),
                        ("missing.py:Thing", "no file")):
        project = tmp_path / "p.json"
        project.write_text(json.dumps({
            "projectName": "p", "nodeNum": 2, "linkNum": 1,
            "nodeLists": [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
                          {"nodeName": "g", "UID": 2, "model": model, "input": ["u"], "output": ["y"]}],
            "linkLists": [{"from": "clock.y", "to": "g.u"}], "coSimulation": {"stepSize": 0.1, "stopTime": 1.0}}))
        for mode in ("--processes", "--in-process"):
            started = time.monotonic()
            res = hycosim("run", str(project), mode, "--runs-dir", str(tmp_path / "runs"))
            took = time.monotonic() - started
            assert res.returncode == 2 and says in res.stderr and "node 'g'" in res.stderr, (model, mode, res.stderr)
            assert res.stderr.count("error:") == 1 and "Traceback" not in res.stderr, res.stderr
            assert not (tmp_path / "runs").exists(), (model, mode)
            assert took < 2.0, took  # ~0.4 s here, most of it the command line's imports


def test_a_node_whose_model_fails_to_import_is_not_started_again(tmp_path):
    """What the launcher can see only by importing it: the node says it cannot load (exit 2)
    and is not retried, since starting it again fails alike."""
    (tmp_path / "broken.py").write_text("import no_such_module_anywhere\n")
    project = tmp_path / "p.json"
    project.write_text(json.dumps({
        "projectName": "p", "nodeNum": 2, "linkNum": 1,
        "nodeLists": [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
                      {"nodeName": "g", "UID": 2, "model": "broken.py:Thing", "input": ["u"], "output": ["y"]}],
        "linkLists": [{"from": "clock.y", "to": "g.u"}],
        "coSimulation": {"stepSize": 0.1, "stopTime": 1.0, "attachTimeout": 20.0}}))
    res = hycosim("run", str(project), "--runs-dir", str(tmp_path / "runs"), "--no-progress", "--restarts", "3")
    assert res.returncode != 0 and "no_such_module_anywhere" in res.stderr, res.stderr
    run = next((tmp_path / "runs").iterdir())
    log = (run / "node-g.stderr.txt").read_text()
    assert "started again" not in log and log.count("no_such_module_anywhere") == 1, log
