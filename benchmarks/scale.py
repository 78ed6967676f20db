"""Scale: 8, 16, 32 trivial nodes (a gain ring) spread over network namespaces, server in its own.

Each node is its own process in one of four client namespaces, joined to the server's
namespace by a veth pair (root and ``ip netns`` needed). Reports macro steps/s and how
the cost per step grows with N (linear growth doubles it per doubling of N).

    sudo python benchmarks/scale.py [--n 8 16 32] [--steps 1000] [--hosts 4] [--timeout 600] [--json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tests.helpers import env  # noqa: E402
from tests.netns import hosts, netns_available  # noqa: E402

from _procs import start, stop_all, wait_all  # noqa: E402


def ring(n: int, steps: int, path: Path) -> Path:
    """A ring of ``n`` gain nodes for ``steps`` steps, written to ``path``; its path."""
    nodes = [{"nodeName": f"n{i}", "UID": i + 1, "model": "gain", "parameters": {"k": 0.5, "b": 1.0},
              "input": ["u"], "output": ["y"]} for i in range(n)]
    links = [{"from": f"n{i}.y", "to": f"n{(i + 1) % n}.u"} for i in range(n)]
    path.write_text(json.dumps({"projectName": f"scale{n}", "nodeNum": n, "nodeLists": nodes, "linkNum": n,
                                "linkLists": links, "coSimulation": {"stepSize": 1.0, "stopTime": float(steps),
                                                                     "stepTimeout": 60.0, "attachTimeout": 120.0}}))
    return path


def run(n: int, steps: int, n_hosts: int, timeout: float) -> float:
    """The ring's steps/s with its nodes spread over ``n_hosts`` network namespaces and the server in
    one of its own."""
    py = [sys.executable, "-m", "hycosim"]
    with tempfile.TemporaryDirectory() as tmp, hosts([f"h{i}" for i in range(n_hosts)], subnet=214) as h:
        cfg = ring(n, steps, Path(tmp) / "scale-ring.json")  # named apart: a test looks for what is left of it
        run_dir = Path(tmp) / "run"
        # Deleting a namespace does not end its processes: each runs in a group of its own,
        # killed below if it outlives the run.
        server = start(h.exec(h.server) + py + ["server", str(cfg), "--listen", "tcp/0.0.0.0:7447",
                                                "--run-dir", str(run_dir)],
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env(), cwd=REPO)
        nodes = []
        try:
            for i in range(n):
                host = f"h{i % n_hosts}"
                nodes.append(start(h.exec(h.clients[host]) + py + ["node", f"n{i}", str(cfg), "--connect",
                                                                   f"tcp/{h.server_address[host]}:7447"],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env(), cwd=REPO))
            _, err = wait_all(server, nodes, timeout)
        except subprocess.TimeoutExpired:
            raise RuntimeError(f"N={n}: timed out after {timeout:g} s (--timeout)") from None
        finally:
            stop_all(server, *nodes)  # after a failure while starting the nodes
        if server.returncode:
            raise RuntimeError(f"N={n}: the server failed:\n{err[-2000:]}")
        return float(json.loads((run_dir / "meta.json").read_text())["steps_per_s"])


def main() -> None:
    """Measure each ring size and print the rates and the cost a step (``--json``: one object a
    line)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[8, 16, 32])
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--hosts", type=int, default=4)
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per run before its processes are killed")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if not netns_available():
        sys.exit("benchmarks/scale.py needs root and ip netns")
    try:
        rates = {n: run(n, args.steps, args.hosts, args.timeout) for n in args.n}
    except RuntimeError as exc:
        sys.exit(f"scale: {exc}")
    base = args.n[0]
    for n, rate in rates.items():
        if args.json:
            print(json.dumps({"system": "hycosim-netns", "n": n, "steps_per_s": rate}))
        else:
            print(f"N={n:>3}: {rate:8.0f} steps/s   cost per step {1e3 / rate:6.2f} ms   "
                  f"× {rates[base] / rate:.2f} of N={base} (linear: × {n / base:.0f})")


if __name__ == "__main__":
    main()
