"""The wire under attack, live: real processes, real Zenoh sessions over TCP on 127.0.0.1.

* a fuzzer on a second Zenoh session (and on the gateway socket) writes structure-aware garbage
  on every key of a running project: the run completes with the same values.csv as without it;
* with credentials and access control, each role may do exactly what it should on exactly its
  keys (a node authenticated with its own password forging frames: benchmarks/fuzz.py, run
  at a small scale by tests/test_benchmarks.py).
"""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import msgpack
import pytest
import zenoh

from hycosim.core import frames
from hycosim.core.config import load_project
from hycosim.transport.keys import SERVER_TOKEN, ProjectKeys
from hycosim.transport.security import router_security
from hycosim.transport.session import ConnectError, client_config, open_session, router_config
from tests.helpers import HYCOSIM, env, free_endpoint, meta, read_rows, REPO, wait_for, write_project
from tests.wire_strategies import examples, forgeable, gateway_streams, payloads, send_to_gateway

NODES = [
    {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
    {"nodeName": "g", "UID": 2, "model": "gain", "parameters": {"k": 0.5}, "input": ["u"], "output": ["y"]},
    {"nodeName": "h", "UID": 3, "model": "gain", "input": ["u"], "output": ["y"]},
]
LINKS = [{"from": "clock.y", "to": "g.u"}, {"from": "g.y", "to": "h.u"}]
UIDS = {n["nodeName"]: n["UID"] for n in NODES}


def _project(path: Path, endpoint: str, **extra) -> Path:
    write_project(path, NODES, LINKS, name="wire", cosim={"stepSize": 0.01, "stopTime": 3.0, "realTime": True,
                                                          "stepTimeout": 10.0}, **extra)
    doc = json.loads(path.read_text())
    doc["serverIP"] = endpoint
    path.write_text(json.dumps(doc))
    return path


def _run(cfg: Path, runs: Path, endpoint: str) -> subprocess.Popen:
    return subprocess.Popen([*HYCOSIM, "run", str(cfg), "--runs-dir", str(runs), "--no-progress", "--listen", endpoint],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env(), cwd=REPO)


def _finish(proc: subprocess.Popen, runs: Path) -> Path:
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, f"{out}\n{err}"
    return next(runs.iterdir())


def _running_dir(runs: Path) -> Path:
    wait_for(lambda: runs.exists() and any((d / "values.csv").exists() and len(read_rows(d)) > 50
                                           for d in runs.iterdir()), 60, "the run's first 50 steps")
    return next(runs.iterdir())


def test_fuzzing_every_key_and_the_gateway_leaves_the_run_and_its_values_unchanged(tmp_path):
    clean_ep, fuzz_ep = free_endpoint(), free_endpoint()
    clean = _finish(_run(_project(tmp_path / "clean.json", clean_ep), tmp_path / "clean", clean_ep), tmp_path / "clean")

    keys = ProjectKeys("wire")
    targets = [keys.up("clock"), keys.up("g"), keys.up("h"), keys.up("nobody"), f"{keys.root}/up/_local",
               keys.down, keys.alive("g"), keys.status]
    corpus = examples(payloads, 1500)
    sends = [(targets[i % len(targets)], p) for i, p in enumerate(corpus * 2)]
    sends = [(k, p) for k, p in sends if not forgeable(p, k, UIDS)]
    streams = examples(gateway_streams(), 60)

    cfg = _project(tmp_path / "fuzz.json", fuzz_ep)
    proc = _run(cfg, tmp_path / "fuzz", fuzz_ep)
    try:
        run_dir = _running_dir(tmp_path / "fuzz")
        with zenoh.open(client_config(fuzz_ep)) as fuzzer:
            for key, payload in sends:
                fuzzer.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)
            # The status queryable, asked with garbage: it answers as a server does.
            answers = [r for p in corpus[:20] for r in fuzzer.get(f"{keys.status}?{p.hex()[:16]}", payload=p,
                                                                   timeout=2.0)]
        send_to_gateway(int(fuzz_ep.rsplit(":", 1)[1]) + 1, streams)
        still_running = proc.poll() is None
        fuzzed = _finish(proc, tmp_path / "fuzz")
    finally:
        if proc.poll() is None:
            proc.kill()
    assert still_running  # every frame went in while the run was on
    assert len(answers) == 20 and all(json.loads(r.ok.payload.to_bytes())["project"] == "wire" for r in answers)
    assert (fuzzed / "values.csv").read_text() == (clean / "values.csv").read_text()
    m = meta(fuzzed)
    on_up = sum(1 for k, _ in sends if "/up/" in k)
    assert sum(m["dropped_frames"].values()) >= on_up
    log = run_dir / "server.log.jsonl"
    assert log.stat().st_size < 256 * 1024  # bounded: a few lines per reason and sender, then summaries
    # Every frame on `down` is one no node can act on; a well-formed REPLAY, or RESTORE naming
    # another node, or a CHECKPOINT, is passed over, not counted as dropped.
    on_down = sum(1 for k, p in sends if k == keys.down and not _passed_over(p))
    for node in UIDS:
        log = fuzzed / f"node-{node}.log.jsonl"
        assert log.stat().st_size < 256 * 1024
        stop = [json.loads(line) for line in log.read_text().splitlines() if '"stop"' in line][-1]
        assert on_down > 0 and sum(stop["dropped"].values()) >= on_down  # each node dropped them all


def test_a_peer_asking_the_status_in_a_loop_gets_the_budgets_answers_and_busy_for_the_rest(tmp_path):
    """Anyone may ask the server's status, and each answer is built while the barrier waits: a
    peer asking as fast as it can (before, it took a fast ring from 3,000 steps/s to 500) gets
    at most the budget's answers and a 'busy' error at once for the rest, each one counted in
    meta.json; `hycosim status` says the server is busy; the run goes on to its end."""
    from hycosim.transport.answer_budget import ANSWERS_PER_S, BURST

    endpoint = free_endpoint()
    proc = _run(_project(tmp_path / "asked.json", endpoint), tmp_path / "asked", endpoint)
    key = ProjectKeys("wire").status
    try:
        _running_dir(tmp_path / "asked")
        ok, busy = 0, []
        with zenoh.open(client_config(endpoint)) as asker:
            # `hycosim status` asks while the loop goes on (until it has its reply)
            status = subprocess.Popen([*HYCOSIM, "status", endpoint, "--timeout", "2"], stdout=subprocess.PIPE,
                                      stderr=subprocess.PIPE, text=True, env=env(), cwd=REPO)
            started = time.monotonic()
            while time.monotonic() - started < 1.0 or (status.poll() is None and time.monotonic() - started < 30):
                for reply in asker.get(key, timeout=2.0):
                    if reply.ok is not None:
                        ok += 1
                    else:
                        busy.append(reply.err.payload.to_bytes())
            took = time.monotonic() - started
            told_out, told_err = status.communicate(timeout=30)
            time.sleep(0.5)  # the bucket refills: an asker at a dashboard's pace is answered again
            again = [r.ok is not None for r in asker.get(key, timeout=2.0)]
        assert proc.poll() is None  # still running: asked all the while
        run_dir = _finish(proc, tmp_path / "asked")
    finally:
        if proc.poll() is None:
            proc.kill()
    assert 1 <= ok <= BURST + ANSWERS_PER_S * took + 1
    assert len(busy) > ok and set(busy) == {f"busy: over {ANSWERS_PER_S:g} status answers a second; "
                                                 "ask again".encode()}
    assert again == [True]
    assert meta(run_dir)["dropped_frames"]["status over budget"] >= len(busy)
    # `hycosim status` amid the loop is answered (a token came free just then) or says the
    # server is busy, never that no server answered
    assert (status.returncode == 0 and "wire: step" in told_out) or (
        status.returncode == 3 and "is busy: over 40 status answers a second" in told_err), (told_out, told_err)


def _replay_for_someone(payload: bytes) -> bool:
    try:
        obj = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception:
        return False
    if not (type(obj) is list and len(obj) > 2 and type(obj[0]) is int and obj[0] == frames.VERSION
            and type(obj[1]) is int and type(obj[2]) is str):
        return False
    if obj[1] == frames.REPLAY:
        return len(obj) == 4 and type(obj[3]) is bytes
    # A RESTORE and a TUNE name their node too: one for another node is passed over, as a REPLAY is.
    try:
        return obj[1] in (frames.RESTORE, frames.TUNE) and frames.decode(payload).node not in ("g", "h")
    except frames.FrameError:
        return False


def _passed_over(payload: bytes) -> bool:
    """A frame on ``down`` a node passes over without counting it dropped: a REPLAY, RESTORE,
    TUNE or INIT for another node, or a CHECKPOINT of a point in range (the server sends each to every
    node, and a node whose step does not end there leaves it, as a slower one does)."""
    try:
        frame = frames.decode(payload)
    except frames.FrameError:
        return False
    if frame.kind == frames.CHECKPOINT:
        return 0 <= frame.step < frames.MAX_STEP
    if frame.kind == frames.INIT:  # an initialisation of other nodes (each node it names drops it)
        return True
    return _replay_for_someone(payload)


# --- access control ----------------------------------------------------------------------

KINDS = ["put", "delete", "declare_subscriber", "liveliness_token", "declare_liveliness_subscriber",
         "liveliness_query", "query", "declare_queryable"]


def _keys() -> dict[str, str]:
    k = ProjectKeys("wire")
    return {"up/self": k.up("g"), "up/other": k.up("clock"), "down": k.down, "alive/self": k.alive("g"),
            "alive/other": k.alive("clock"), "alive/server": k.alive(SERVER_TOKEN), "status": k.status}


def _probe(router: zenoh.Session, client: zenoh.Session, keys: dict[str, str]) -> set[tuple[str, str]]:
    """Which (message kind, key) the client could use, each tried for real through the router.
    Each kind is tried in rounds (see ``_in_rounds``): a refused use never gets through, so a
    second try of what did not only spares a permitted one that was slow on a loaded machine."""
    by_key = {v: n for n, v in keys.items()}
    root = "hycosim/wire/**"

    def written(pending: set[tuple[str, str]]) -> set[tuple[str, str]]:
        got: list[zenoh.Sample] = []
        sub = router.declare_subscriber(root, got.append)
        time.sleep(0.3)
        for name in {name for _, name in pending}:
            client.put(keys[name], b"probe", congestion_control=zenoh.CongestionControl.BLOCK)
            client.delete(keys[name])
        time.sleep(0.5)
        sub.undeclare()
        return {("put" if s.kind == zenoh.SampleKind.PUT else "delete", by_key[str(s.key_expr)]) for s in got}

    passed = _in_rounds(written, {(kind, name) for name in keys for kind in ("put", "delete")})

    subs = {name: client.declare_subscriber(key, zenoh.handlers.FifoChannel(16)) for name, key in keys.items()}
    time.sleep(0.4)

    def heard(pending: set[str]) -> set[str]:
        for name in pending:
            router.put(keys[name], b"to-client")
        time.sleep(0.5)
        return {name for name in pending if subs[name].try_recv() is not None}

    passed |= {("declare_subscriber", n) for n in _in_rounds(heard, set(keys))}
    for s in subs.values():
        s.undeclare()

    tokens = [client.liveliness().declare_token(key) for key in keys.values()]

    def seen(_: set[str]) -> set[str]:
        time.sleep(0.5)
        return {by_key[k] for r in router.liveliness().get(root, timeout=1.0) if r.ok is not None
                and (k := str(r.ok.key_expr)) in by_key}

    passed |= {("liveliness_token", n) for n in _in_rounds(seen, set(keys))}
    for t in tokens:
        t.undeclare()
    time.sleep(0.3)

    server_tokens = [router.liveliness().declare_token(key) for key in keys.values()]
    time.sleep(0.3)
    # Queried before the watchers below are declared and undeclared: in one CI run every
    # query the monitor was allowed went unanswered in both rounds right after those undeclares.
    passed |= {("liveliness_query", n) for n in _replied(lambda k: client.liveliness().get(k, timeout=2.0), keys)}
    watchers = {name: client.liveliness().declare_subscriber(key, zenoh.handlers.FifoChannel(16), history=True)
                for name, key in keys.items()}

    def told(pending: set[str]) -> set[str]:
        time.sleep(0.5)
        return {name for name in pending if watchers[name].try_recv() is not None}

    passed |= {("declare_liveliness_subscriber", n) for n in _in_rounds(told, set(keys))}
    for w in watchers.values():
        w.undeclare()
    for t in server_tokens:
        t.undeclare()

    passed |= {("query", n) for n in _answered(answering=router, asking=client, keys=keys)}
    passed |= {("declare_queryable", n) for n in _answered(answering=client, asking=router, keys=keys)}
    return passed


def _in_rounds(attempt: Callable[[set], set], names: set) -> set:
    """The names (or pairs) that got through ``attempt(pending)``, tried twice more for those that did not:
    in one make test a permitted use was not through within its wait on the loaded machine,
    and a refused one never gets through however often it is tried."""
    found = attempt(set(names))
    for _ in range(2):
        if not names - found:
            break
        found |= attempt(names - found)
    return found


def _replied(ask, keys: dict[str, str]) -> set[str]:
    """The names whose query (``ask(key)``) had an answer, in rounds as ``_in_rounds`` tries them.
    A round's queries are all sent before any is waited on, so that the ones refused (which
    wait out their timeout) cost it once a round."""
    def answered(pending: set[str]) -> set[str]:
        sent = {name: ask(keys[name]) for name in pending}
        return {name for name, replies in sent.items() if any(r.ok is not None for r in replies)}

    return _in_rounds(answered, set(keys))


def _answered(answering: zenoh.Session, asking: zenoh.Session, keys: dict[str, str]) -> set[str]:
    """The keys on which ``asking`` had an answer from a queryable ``answering`` declared there."""
    queryables = [answering.declare_queryable(key, lambda q: q.reply(q.key_expr, b"answer")) for key in keys.values()]
    time.sleep(0.4)
    found = _replied(lambda key: asking.get(key, timeout=2.0), keys)
    for q in queryables:
        q.undeclare()
    return found


def _secure(tmp_path: Path, endpoint: str) -> Path:
    (tmp_path / "creds.txt").write_text("server:s-pw\nclock:c-pw\ng:g-pw\nh:h-pw\nwatcher:w-pw\n")
    return _project(tmp_path / "secure.json", endpoint, security={"credentials": "creds.txt"})


def test_access_control_grants_each_permission_on_exactly_its_keys(tmp_path):
    endpoint = free_endpoint()
    loaded = load_project(_secure(tmp_path, endpoint))
    keys = _keys()
    with open_session(router_config(endpoint, security=router_security(loaded, endpoint)), endpoint) as router:
        found = {}
        for role, user, password in (("node", "g", "g-pw"), ("monitor", "watcher", "w-pw")):
            with open_session(client_config(endpoint, user=user, password=password), endpoint) as client:
                found[role] = _probe(router, client, keys)
        with pytest.raises(ConnectError):
            open_session(client_config(endpoint, timeout_s=2.0, user="g", password="wrong"), endpoint)
        with pytest.raises(ConnectError):
            open_session(client_config(endpoint, timeout_s=2.0), endpoint)
    assert found["node"] == {("put", "up/self"), ("declare_subscriber", "down"), ("liveliness_token", "alive/self"),
                             ("declare_liveliness_subscriber", "alive/server"), ("liveliness_query", "alive/self"),
                             ("liveliness_query", "alive/server"), ("query", "status")}
    everything = set(keys)
    assert found["monitor"] == ({("declare_subscriber", k) for k in everything}
                                | {("declare_liveliness_subscriber", k) for k in everything}
                                | {("liveliness_query", k) for k in everything} | {("query", "status")})


# The forgery by an authenticated node (releases on `down`, outputs under other nodes' keys, tokens
# and queryables it has no right to) runs in tests/test_benchmarks.py through benchmarks/fuzz.py.
