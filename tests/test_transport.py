"""The transport: the low-latency frame limit (enforced with a clear error, and can be lifted),
Zenoh's runtime threads, every node knowing the server's liveliness token, and nodes started
before their server attaching as soon as it listens."""

from __future__ import annotations

import json
import os
import subprocess
import threading
import time

from hycosim.transport.session import SHARED_RUNTIME, client_config, open_session, router_config
from tests.helpers import HYCOSIM, REPO, free_endpoint, hycosim, meta, read_rows, run_project, write_project

LIMIT = 32 * 1024


def _text_node(name: str, uid: int, size: int, outputs: list[str], inputs: list[str] | None = None) -> dict:
    return {"nodeName": name, "UID": uid, "model": "tests.nodes:Text", "parameters": {"size": size},
            "input": [{"name": p, "type": "String"} for p in inputs or []],
            "output": [{"name": p, "type": "String"} for p in outputs]}


def _run(tmp_path, nodes, links=None, **cosim):
    cfg = write_project(tmp_path / "p.json", nodes, links,
                        cosim={"stepSize": 0.1, "stopTime": 0.5, "stepTimeout": 10.0, **cosim})
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress", timeout=120)
    return res, sorted((tmp_path / "runs").iterdir())[0]


def test_outputs_over_the_low_latency_limit_stop_the_run_naming_node_and_port(tmp_path):
    res, run_dir = _run(tmp_path, [_text_node("big", 1, 40_000, ["small", "blob"])])
    text = res.stdout + res.stderr
    assert res.returncode != 0
    assert "'big'" in text and "blob (40" in text and f"{LIMIT} bytes" in text and '"lowLatency": false' in text
    assert meta(run_dir)["status"] == "failed"


def test_outputs_that_outgrow_the_limit_mid_run_stop_it_naming_node_and_port_rows_kept(tmp_path):
    """A node's steps after the first take its flat path, which measures each frame itself."""
    node = _text_node("big", 1, 10, ["small", "blob"])
    node["parameters"].update(grow_at=3, grown=40_000)
    res, run_dir = _run(tmp_path, [node])
    text = res.stdout + res.stderr
    assert res.returncode != 0
    assert "'big'" in text and "at step 2" in text and "blob (40" in text and f"{LIMIT} bytes" in text
    assert meta(run_dir)["status"] == "failed"
    rows = (run_dir / "values.csv").read_text().splitlines()[1:]
    assert [r.split(",")[0] for r in rows] == ["0", "1", "2"]


def test_a_release_over_the_limit_names_the_node_whose_inputs_fill_it(tmp_path):
    # 20 kB out of "src" is within the limit; fanned out to two inputs of "dst", the release is not.
    nodes = [_text_node("src", 1, 20_000, ["s"]), _text_node("dst", 2, 5, ["y"], inputs=["a", "b"])]
    links = [{"from": "src.s", "to": "dst.a"}, {"from": "src.s", "to": "dst.b"}]
    res, run_dir = _run(tmp_path, nodes, links)
    text = res.stdout + res.stderr
    assert res.returncode == 3
    assert "release of step 0" in text and "dst (40" in text and '"lowLatency": false' in text
    rows = read_rows(run_dir)  # the point whose release failed is still recorded
    assert [r["step"] for r in rows] == ["0"] and rows[0]["dst.a"].startswith("0:xxx")


def test_the_standard_transport_carries_large_frames(tmp_path):
    nodes = [_text_node("src", 1, 40_000, ["s"]), _text_node("dst", 2, 5, ["y"], inputs=["a", "b"])]
    links = [{"from": "src.s", "to": "dst.a"}, {"from": "src.s", "to": "dst.b"}]
    res, run_dir = _run(tmp_path, nodes, links, lowLatency=False)
    assert res.returncode == 0, res.stdout + res.stderr
    rows = read_rows(run_dir)
    assert len(rows) == 6
    # Jacobi: the input at step k is src's output at step k, which counts steps in its first characters.
    assert [r["dst.a"][:2] for r in rows] == [f"{k}:" for k in range(6)]
    assert all(len(r["dst.b"]) == 40_000 for r in rows)


def _run_with_env(tmp_path, cfg, **env):
    base = {k: v for k, v in os.environ.items() if k != "ZENOH_RUNTIME"}
    res = subprocess.run([*HYCOSIM, "run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress"],
                         capture_output=True, text=True, timeout=120, cwd=REPO,
                         env={**base, "PYTHONPATH": str(REPO), **env})
    assert res.returncode == 0, res.stderr
    return sorted((tmp_path / "runs").iterdir())[-1]


def test_runs_record_their_transport_and_zenoh_runtime(tmp_path):
    cfg = write_project(tmp_path / "p.json", [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]}],
                        cosim={"stepSize": 0.1, "stopTime": 0.3})
    m = meta(_run_with_env(tmp_path, cfg))
    assert m["lowLatency"] is True and m["zenoh_runtime"] == SHARED_RUNTIME
    assert m["waitStrategy"] == "auto" and isinstance(m["server_polls"], bool)
    # A runtime the user sets is left alone (the server records what it ran with).
    own = "(app: (worker_threads: 3))"
    assert meta(_run_with_env(tmp_path, cfg, ZENOH_RUNTIME=own))["zenoh_runtime"] == own


def test_every_node_knows_the_servers_token_from_the_start(tmp_path):
    # A node learns that the server went (a cut link) only from the server's liveliness token;
    # a node that attached without hearing of the token would never notice. Eight attaches.
    n = 8
    nodes = [{"nodeName": f"n{i}", "UID": i + 1, "model": "gain", "input": ["u"], "output": ["y"]} for i in range(n)]
    links = [{"from": f"n{i}.y", "to": f"n{(i + 1) % n}.u"} for i in range(n)]
    run = run_project(write_project(tmp_path / "p.json", nodes, links, cosim={"stepSize": 0.1, "stopTime": 2.0}),
                      tmp_path / "runs")
    for i in range(n):
        events = [json.loads(line)["event"] for line in (run / f"node-n{i}.log.jsonl").read_text().splitlines()]
        assert events.count("server seen") == 1, (f"n{i}", events)
        assert "server back" not in events and events.index("server seen") < events.index("stop")


def test_the_servers_router_does_not_wait_for_peers_it_cannot_find():
    """zenoh.open in router mode waits scouting/delay (500 ms by default) for peers found by
    scouting; the server scouts for none, and every run waited with its nodes attached
    (docs/wire.md has the figures). A client's open has no such wait to lose."""
    conf = router_config(free_endpoint())
    assert conf.get_json("scouting/multicast/enabled") == "false"
    assert json.loads(conf.get_json("scouting/delay")) == 0
    assert json.loads(conf.get_json("listen/endpoints")) != []


def test_a_node_started_before_its_server_attaches_soon_after_the_server_listens(tmp_path):
    """Nodes usually start with their server, before it listens; Zenoh's own retries (1 s
    apart, then 2 s) kept them waiting up to a second after it did (0.3 s a run, in the median)."""
    endpoint = free_endpoint()
    opened: list[float] = []

    def node() -> None:
        session = open_session(client_config(endpoint, timeout_s=20.0), endpoint)
        opened.append(time.monotonic())
        session.close()

    client = threading.Thread(target=node)
    client.start()
    time.sleep(1.5)  # the node's first tries are refused
    listening = time.monotonic()
    with open_session(router_config(endpoint), endpoint):
        client.join(timeout=30)
    assert opened, "the node never connected"
    # Zenoh's defaults would retry at 1 s and 3 s after the first try: 1.5 s after it listens.
    assert opened[0] - listening < 1.0, f"attached {opened[0] - listening:.2f} s after the server listened"
