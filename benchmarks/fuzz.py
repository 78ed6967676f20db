"""Fuzz and forgery: a running project under hostile frames, against the same run left alone.

Two experiments, each a deterministic three-node project (ramp → gain → gain, H = 10 ms,
paced at real time) run once clean and once attacked, every process its own, on loopback:

* **fuzz** (no security): ``--frames`` structure-aware frames and raw bytes
  (``tests/wire_strategies.py``, drawn derandomized) spread round-robin over every key of the
  project (each node's ``up``, an unknown node's, ``up/_local``, ``down``, a liveliness key,
  ``status``) from a second Zenoh session, plus ``--streams`` connections writing garbage to
  the TCP gateway. Frames that the rightful sender could have written (an output with the
  node's UID for a step of the run, a STEP or STOP on ``down``) are left out: without
  credentials nobody can tell them from the real ones; that is the second experiment's case.
* **forgery** (credentials and access control on): a node authenticated with its own password
  writes ``--forged`` well-formed frames on every key it does not own: releases and STOPs on
  ``down``, outputs under the other nodes' keys and UIDs, puts on liveliness and status keys.

Targets: every process ends well (exit 0), ``values.csv`` identical to the clean run's, the
server's log at most 1 MiB (fuzz), and nothing forged reaching the server or a node.

    python benchmarks/fuzz.py [--frames 100000] [--streams 500] [--forged 10000] [--seconds 12] [--json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import _table  # noqa: E402

import zenoh  # noqa: E402

from benchmarks._procs import free_port  # noqa: E402
from hycosim.core import frames  # noqa: E402
from hycosim.transport.keys import SERVER_TOKEN, ProjectKeys  # noqa: E402
from hycosim.transport.session import client_config  # noqa: E402
from tests.wire_strategies import examples, forgeable, gateway_streams, payloads, send_to_gateway  # noqa: E402

NODES = [
    {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
    {"nodeName": "g", "UID": 2, "model": "gain", "parameters": {"k": 0.5}, "input": ["u"], "output": ["y"]},
    {"nodeName": "h", "UID": 3, "model": "gain", "input": ["u"], "output": ["y"]},
]
UIDS = {n["nodeName"]: n["UID"] for n in NODES}
BLOCK = zenoh.CongestionControl.BLOCK


def project(folder: Path, port: int, stop_time: float, secure: bool) -> Path:
    """The fuzzed project (a clock and two gains, paced in real time) in ``folder``, with credentials
    and access control where ``secure``; its path."""
    doc = {"projectName": "fuzz", "serverIP": f"tcp/127.0.0.1:{port}", "nodeNum": 3, "nodeLists": NODES,
           "linkNum": 2, "linkLists": [{"from": "clock.y", "to": "g.u"}, {"from": "g.y", "to": "h.u"}],
           "coSimulation": {"stepSize": 0.01, "stopTime": stop_time, "realTime": True, "stepTimeout": 30.0}}
    if secure:
        (folder / "creds.txt").write_text("server:s-pw\nclock:c-pw\ng:g-pw\nh:h-pw\n")
        doc["security"] = {"credentials": "creds.txt"}
    path = folder / "p.json"
    path.write_text(json.dumps(doc))
    return path


def start_run(cfg: Path, runs: Path, port: int) -> subprocess.Popen:
    """``hycosim run`` of ``cfg``, its server listening on ``port``."""
    return subprocess.Popen([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", str(runs),
                             "--no-progress", "--listen", f"tcp/127.0.0.1:{port}"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)


def wait_started(runs: Path, timeout: float = 60.0) -> Path:
    """The run directory under ``runs`` once its values.csv holds 50 rows; RuntimeError after
    ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for d in runs.glob("*"):
            values = d / "values.csv"
            if values.exists() and values.read_text().count("\n") > 50:
                return d
        time.sleep(0.05)
    raise SystemExit("the run did not start within a minute")


def finish(proc: subprocess.Popen, runs: Path) -> tuple[int, Path, str]:
    """Wait for the run to end: its exit code, run directory and output."""
    out, err = proc.communicate(timeout=300)
    return proc.returncode, next(runs.iterdir()), (out + err).strip()


def clean_run(folder: Path, stop_time: float, secure: bool) -> Path:
    """The project run alone, for the attacked runs to be compared with; its run directory."""
    folder.mkdir()
    port = free_port()
    code, run_dir, text = finish(start_run(project(folder, port, stop_time, secure), folder / "runs", port),
                                 folder / "runs")
    if code != 0:
        raise SystemExit(f"the clean run failed: {text}")
    return run_dir


def fuzz(tmp: Path, n_frames: int, n_streams: int, stop_time: float) -> dict:
    """Run the project while fuzzed frames go to every key and garbage to the gateway; what was sent,
    what was dropped, and whether the values came out as the clean run's."""
    clean = clean_run(tmp / "clean", stop_time, secure=False)
    keys = ProjectKeys("fuzz")
    targets = [keys.up("clock"), keys.up("g"), keys.up("h"), keys.up("nobody"), f"{keys.root}/up/_local",
               keys.down, keys.alive("g"), keys.status]
    made = time.perf_counter()
    corpus = examples(payloads, min(n_frames, 5000))
    streams = examples(gateway_streams(), min(n_streams, 2000))
    made = time.perf_counter() - made
    sends = []
    i = 0
    while len(sends) < n_frames:  # the corpus again and again, each time on other keys
        payload = corpus[i % len(corpus)]
        key = targets[(i + i // len(corpus)) % len(targets)]
        i += 1
        if not forgeable(payload, key, UIDS):
            sends.append((key, payload))
    folder = tmp / "fuzzed"
    folder.mkdir()
    port = free_port()
    proc = start_run(project(folder, port, stop_time, secure=False), folder / "runs", port)
    run_dir = wait_started(folder / "runs")
    began = time.perf_counter()
    with zenoh.open(client_config(f"tcp/127.0.0.1:{port}")) as fuzzer:
        for key, payload in sends:
            fuzzer.put(key, payload, congestion_control=BLOCK)
    sent_s = time.perf_counter() - began
    connections = send_to_gateway(port + 1, (streams * (n_streams // len(streams) + 1))[:n_streams])
    during = proc.poll() is None
    code, run_dir, text = finish(proc, folder / "runs")
    meta = json.loads((run_dir / "meta.json").read_text())
    return {
        "experiment": "fuzz", "frames": len(sends), "gateway_connections": connections,
        "frames_per_s": len(sends) / sent_s, "corpus_s": made, "all_sent_during_run": during,
        "exit_code": code, "identical_values": (run_dir / "values.csv").read_text() == (clean / "values.csv").read_text(),
        "dropped_frames": meta.get("dropped_frames", {}), "dropped_total": sum(meta.get("dropped_frames", {}).values()),
        "frames_on_up": sum(1 for k, _ in sends if "/up/" in k),
        "server_log_bytes": (run_dir / "server.log.jsonl").stat().st_size,
        "node_log_bytes": {n: (run_dir / f"node-{n}.log.jsonl").stat().st_size for n in UIDS},
        "message": text.splitlines()[-1] if text else "",
    }


def forgery(tmp: Path, n_forged: int, stop_time: float) -> dict:
    """Run the secured project while an authenticated node forges frames on every key it may use; what
    reached the server and the nodes, and whether the values came out as the clean run's."""
    clean = clean_run(tmp / "secure-clean", stop_time, secure=True)
    folder = tmp / "secure-attacked"
    folder.mkdir()
    port = free_port()
    proc = start_run(project(folder, port, stop_time, secure=True), folder / "runs", port)
    wait_started(folder / "runs")
    keys = ProjectKeys("fuzz")
    kinds = {"down STEP": 0, "down STOP": 0, "down START": 0, "up/clock": 0, "up/h": 0, "alive": 0, "status": 0}
    with zenoh.open(client_config(f"tcp/127.0.0.1:{port}", user="g", password="g-pw")) as forger:
        for i in range(n_forged):
            k = 60 + i // 7
            which = i % 7
            if which == 0:
                payload = frames.encode(frames.STEP, k, k * 0.01, 0.01, "free",
                                        {"clock": [], "g": [99.0], "h": [99.0]}, [], {})
                key, kind = keys.down, "down STEP"
            elif which == 1:
                key, payload, kind = keys.down, frames.encode(frames.STOP, k, "forged"), "down STOP"
            elif which == 2:
                key, payload, kind = keys.down, frames.encode(frames.START, "x", 0.0, 0.01, 0.0, None, {}), "down START"
            elif which == 3:
                key, payload, kind = keys.up("clock"), frames.encode(frames.OUTPUTS, 1, k, k * 0.01, [-1.0, -1.0]), "up/clock"
            elif which == 4:
                key, payload, kind = keys.up("h"), frames.encode(frames.OUTPUTS, 3, k, k * 0.01, [-1.0]), "up/h"
            elif which == 5:
                key, payload, kind = keys.alive(SERVER_TOKEN), frames.encode(frames.LIVE, "_server", False), "alive"
            else:
                key, payload, kind = keys.status, b'{"project": "forged"}', "status"
            forger.put(key, payload, congestion_control=BLOCK)
            kinds[kind] += 1
        # Declarations it has no right to: another node's token, an answer on status.
        token = forger.liveliness().declare_token(keys.alive("clock"))
        queryable = forger.declare_queryable(keys.status, lambda q: q.reply(keys.status, b"forged"))
        time.sleep(0.5)
        token.undeclare()
        queryable.undeclare()
    during = proc.poll() is None
    code, run_dir, text = finish(proc, folder / "runs")
    meta = json.loads((run_dir / "meta.json").read_text())
    node_drops = sum((run_dir / f"node-{n}.log.jsonl").read_text().count("frame dropped") for n in UIDS)
    return {
        "experiment": "forgery", "frames": n_forged, "by_key": kinds, "all_sent_during_run": during,
        "exit_code": code, "identical_values": (run_dir / "values.csv").read_text() == (clean / "values.csv").read_text(),
        "reached_server": sum(meta.get("dropped_frames", {}).values()), "reached_nodes": node_drops,
        "message": text.splitlines()[-1] if text else "",
    }


def main() -> None:
    """Run the fuzz and the forgery experiments and print them (``--json``: one object each)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100_000)
    ap.add_argument("--streams", type=int, default=500, help="garbage connections to the gateway")
    ap.add_argument("--forged", type=int, default=10_000)
    ap.add_argument("--seconds", type=float, default=12.0, help="simulated (= wall) seconds of each run")
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="hycosim-fuzz-") as tmp:
        results = [fuzz(Path(tmp), args.frames, args.streams, args.seconds),
                   forgery(Path(tmp), args.forged, args.seconds)]
    f, g = results
    _table.write(args.table, _table.Table(
        f"A run of {args.seconds:g} s under attack against the same run left alone:",
        ["attack", "exit", "`values.csv` identical", "what became of it"],
        [[f"{f['frames']:,} fuzzed frames on every key, {f['gateway_connections']} garbage connections to the gateway",
          f["exit_code"], f["identical_values"], f"{f['dropped_total']:,} dropped and counted by the server"],
         [f"{g['frames']:,} forged frames from an authenticated node on keys it does not own", g["exit_code"],
          g["identical_values"], f"reached the server: {g['reached_server']}; reached a node: {g['reached_nodes']}"]]))
    if args.json:
        for r in results:
            print(json.dumps(r))
        return
    print(f"fuzz: {f['frames']:,} frames ({f['frames_per_s']:,.0f}/s, {f['frames_on_up']:,} on up keys) and "
          f"{f['gateway_connections']} gateway connections during the run: {f['all_sent_during_run']}")
    print(f"  exit {f['exit_code']}; values.csv identical to the clean run: {f['identical_values']}; "
          f"dropped and counted by the server: {f['dropped_total']:,} {f['dropped_frames']}")
    print("  (frames on up keys that were not counted never reached the server: a peer that writes faster than the "
          "server reads is held back by Zenoh's congestion control, and its link closed once its lease runs out)")
    print(f"  server log {f['server_log_bytes'] / 1024:.1f} KiB; node logs "
          + ", ".join(f"{n} {b / 1024:.1f} KiB" for n, b in f["node_log_bytes"].items()))
    print(f"forgery (credentials + ACL): {g['frames']:,} frames by node g on keys it does not own {g['by_key']}")
    print(f"  exit {g['exit_code']}; values.csv identical: {g['identical_values']}; reached the server: "
          f"{g['reached_server']}; reached a node: {g['reached_nodes']}")


if __name__ == "__main__":
    main()
