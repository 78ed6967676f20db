"""A peer asking the server's status in a loop: what it costs a fast run, against the same run left alone.

Anyone who reaches the server may ask its status queryable, and an answer is built while
the barrier waits. The server answers ``server.answer_budget.ANSWERS_PER_S`` questions a
second and replies "busy" to the rest. Three ways to run the same ring of 2 nodes
(benchmarks/barrier.py's, y = 0.5·u + 1, each node its own process, on loopback), the
rounds interleaved, medians of steps/s:

* **plain**: nobody asks;
* **busy core**: a process spinning on a core beside it, the cost of any busy process;
* **flood, waiting**: a Zenoh client asking the status one question at a time, the next as
  soon as the last is answered, from a process of its own (on the machine too, as an
  attacker's process would be);
* **flood, firing**: the same client sending its questions without waiting for replies.

Goal: a flood costs the run about what a process taking a core costs it (its ratio to plain
near busy core's), and every question past the budget is answered "busy" and counted.
Measured 2026-11-27 on the project's 2-core VM (10,000 steps, 2 rounds): without the budget
0.17 (waiting) and 0.26 (firing) of plain, busy core 0.66–0.72; with it 0.45 and 0.78. The
waiting flooder is answered "busy" at once and asks again, some 1,300 questions a second:
what remains is Zenoh's and Python's handling of each question in the server.

    python benchmarks/status_flood.py [--steps 20000] [--repeat 3] [--timeout 300] [--json]
"""

from __future__ import annotations

import argparse
import json
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import _table
from _procs import free_port, kill_group, start

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

from barrier import ring_config  # noqa: E402

# The flooder: asks until interrupted; prints its tally (answers, busy replies) each half second
# and once more as it ends, so that the last line is the whole tally however loaded the machine.
_FLOODER = r"""
import sys, time
from hycosim.transport.keys import ProjectKeys
from hycosim.transport.session import client_config, open_session
endpoint, project = sys.argv[1], sys.argv[2]
waits = sys.argv[3] == "waits"
key, tally = ProjectKeys(project).status, [0, 0]
def count(reply):  # an answer, or the server's "busy" (a timeout's error, as the run ends, is neither)
    if reply.ok is not None:
        tally[0] += 1
    elif reply.err is not None and reply.err.payload.to_bytes().startswith(b"busy: "):
        tally[1] += 1
try:
    session = None
    while session is None:  # a short attempt, again and again: one of 2 s could outlast a short run
        try:
            session = open_session(client_config(endpoint, timeout_s=0.1), endpoint)
        except Exception:
            time.sleep(0.01)
    shown = time.monotonic()
    while True:
        if waits:  # one question at a time, the next as soon as the last is answered
            for reply in session.get(key, timeout=1.0):
                count(reply)
        else:  # questions sent without waiting for their replies
            session.get(key, count, timeout=1.0)
        if time.monotonic() - shown > 0.5:
            print(*tally, flush=True)
            shown = time.monotonic()
except KeyboardInterrupt:
    print(*tally, flush=True)
"""


def one_run(kind: str, steps: int, timeout: float) -> dict:
    """One ring run with ``kind`` beside it; its steps/s, and the flooder's tally and meta's count."""
    with tempfile.TemporaryDirectory() as tmp:
        cfg = ring_config(2, steps, Path(tmp) / "ring.json")
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        beside, lines = None, []
        if kind == "busy core":
            beside = start([sys.executable, "-c", "while True: pass"])
        elif kind.startswith("flood"):
            beside = start([sys.executable, "-c", _FLOODER, endpoint, json.loads(cfg.read_text())["projectName"],
                            "waits" if kind == "flood, waiting" else "fires"], cwd=REPO, stdout=subprocess.PIPE, text=True)
            reader = threading.Thread(target=lambda: lines.extend(beside.stdout), daemon=True)
            reader.start()
        try:
            run = start([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", tmp, "--no-progress",
                         "--listen", endpoint], cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            try:
                _, err = run.communicate(timeout=timeout)
            except subprocess.TimeoutExpired:
                kill_group(run)
                raise RuntimeError(f"{kind}: the run passed --timeout {timeout:g} s") from None
        finally:
            if beside is not None:
                if kind.startswith("flood"):  # its whole tally, printed as it ends
                    beside.send_signal(signal.SIGINT)
                    try:
                        beside.wait(timeout=10)
                    except subprocess.TimeoutExpired:
                        pass
                kill_group(beside)
                beside.wait()
                if kind.startswith("flood"):
                    reader.join(timeout=5)
        if run.returncode:
            raise RuntimeError(f"{kind}: the run failed ({run.returncode}): {err[-600:]}")
        meta = json.loads(next(Path(tmp).glob("ring*/meta.json")).read_text())
        ok, busy = (int(x) for x in lines[-1].split()) if lines else (0, 0)
        return {"steps_per_s": float(meta["steps_per_s"]), "answered": ok, "busy": busy,
                "counted": meta.get("dropped_frames", {}).get("status over budget", 0)}


def main() -> None:
    """Measure a fast run's rate while peers ask its status in a loop, against the same run left alone;
    print the figures (``--json``: one object)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--repeat", type=int, default=3, help="rounds of the four kinds, interleaved")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds a run may take")
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    args = ap.parse_args()
    kinds = ["plain", "busy core", "flood, waiting", "flood, firing"]
    runs: dict[str, list[dict]] = {k: [] for k in kinds}
    try:
        for r in range(args.repeat):
            for kind in kinds if r % 2 == 0 else kinds[::-1]:
                runs[kind].append(one_run(kind, args.steps, args.timeout))
    except RuntimeError as exc:
        sys.exit(f"status_flood: {exc}")
    median = {k: statistics.median(x["steps_per_s"] for x in v) for k, v in runs.items()}
    result = {"steps": args.steps, "repeat": args.repeat, "median_steps_per_s": median,
              "ratio_to_plain": {k: median[k] / median["plain"] for k in kinds},
              "floods": {k: {"answered": [x["answered"] for x in runs[k]], "busy": [x["busy"] for x in runs[k]],
                             "counted_busy": [x["counted"] for x in runs[k]]} for k in kinds if k.startswith("flood")}}
    _table.write(args.table, _table.Table(
        f"A ring of 2, {args.steps:,} steps, medians of {args.repeat} interleaved rounds:",
        ["beside the run", "steps/s", "against plain", "told busy"],
        [[kind, _table.rate(median[kind]), f"{result['ratio_to_plain'][kind]:.2f}",
          ", ".join(f"{b:,}" for b in result["floods"][kind]["busy"]) if kind in result["floods"] else None]
         for kind in kinds]))
    if args.json:
        print(json.dumps(result, indent=1))
        return
    print(f"ring of 2, {args.steps} steps, {args.repeat} rounds interleaved (medians):")
    for k in kinds:
        print(f"  {k:15s} {median[k]:8.0f} steps/s  {result['ratio_to_plain'][k]:.2f} of plain")
    for k, f in result["floods"].items():
        print(f"  {k}: answered {f['answered']} times, told busy {f['busy']} (the server counted {f['counted_busy']})")


if __name__ == "__main__":
    main()
