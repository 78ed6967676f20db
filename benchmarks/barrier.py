"""Macro-step barrier throughput: hycosim against HELICS (tcp, zmq), mosaik 3 and a plain Zenoh barrier.

One workload for every system, in one run: N nodes, each its own OS process, in a ring,
one float in and out each, y = 0.5·u + 1, for 3000 macro steps; N = 2, 4, 8, 16.
Rates count macro steps per second of the stepping loop only (start-up excluded).
Processes are not pinned to cores: on 2 cores the scheduler decides, as it would for a user.

    python benchmarks/barrier.py [--n 2 4] [--steps 3000] [--repeat 3] [--systems hycosim helics-tcp ...]
                                 [--wait-strategy auto|block|yield] [--json]

On a small machine one run of any system scatters by ±20 % (who shares a core with whom
is the scheduler's choice), so every system runs ``--repeat`` times, the rounds
interleaved (system after system, then again), and the table shows the median.

HELICS and mosaik come from the optional extra: pip install -e '.[bench]'.
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
SYSTEMS = ["hycosim", "zenoh-floor", "helics-tcp", "helics-zmq", "mosaik"]


def _port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def ring_config(n: int, steps: int, path: Path, wait_strategy: str = "auto") -> Path:
    nodes = [{"nodeName": f"n{i}", "UID": i + 1, "model": "gain", "parameters": {"k": 0.5, "b": 1.0},
              "input": ["u"], "output": ["y"]} for i in range(n)]
    links = [{"from": f"n{i}.y", "to": f"n{(i + 1) % n}.u"} for i in range(n)]
    doc = {"projectName": f"ring{n}", "serverIP": f"127.0.0.1:{_port()}", "nodeNum": n, "nodeLists": nodes,
           "linkNum": n, "linkLists": links,
           "coSimulation": {"stepSize": 1.0, "stopTime": float(steps), "stepTimeout": 30.0,
                            "waitStrategy": wait_strategy}}
    path.write_text(json.dumps(doc))
    return path


def run_hycosim(n: int, steps: int, wait_strategy: str) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        cfg = ring_config(n, steps, Path(tmp) / "ring.json", wait_strategy)
        res = subprocess.run([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", tmp, "--no-progress"],
                             capture_output=True, text=True, timeout=600, cwd=REPO)
        if res.returncode:
            logs = "".join(f"--- {p.name}\n{p.read_text()[-800:]}" for p in Path(tmp).glob("ring*/*.stderr.txt"))
            raise RuntimeError(res.stderr + logs)
        meta = json.loads(next(Path(tmp).glob("ring*/meta.json")).read_text())
        return float(meta["steps_per_s"])


def run_zenoh_floor(n: int, steps: int, wait_strategy: str) -> float:
    res = subprocess.run([sys.executable, str(HERE / "_zenoh_floor.py"), "server", f"tcp/127.0.0.1:{_port()}",
                          str(n), str(steps), wait_strategy], capture_output=True, text=True, timeout=600)
    if res.returncode:
        raise RuntimeError(res.stderr)
    return float(res.stdout.split()[-1])


def run_helics(core: str, n: int, steps: int) -> float:
    port = _port()
    script = str(HERE / "_helics_fed.py")
    broker = subprocess.Popen([sys.executable, script, "broker", core, str(n), str(port)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    feds = [subprocess.Popen([sys.executable, script, "fed", core, str(n), str(i), str(steps), str(port)],
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True) for i in range(n)]
    try:
        out = feds[0].communicate(timeout=600)[0]
        for f in feds[1:]:
            f.wait(timeout=60)
        broker.wait(timeout=60)
    finally:
        for p in (broker, *feds):
            if p.poll() is None:
                p.kill()
    return float(out.split()[0])


def run_mosaik(n: int, steps: int) -> float:
    code = f"""
import sys, time, mosaik, logging
from loguru import logger
logger.remove()
cfg = {{f"S{{i}}": {{"cmd": sys.executable + " {HERE / '_mosaik_gain.py'} %(addr)s"}} for i in range({n})}}
world = mosaik.World(cfg)
ents = [world.start(f"S{{i}}").Gain() for i in range({n})]
for i in range({n}):
    world.connect(ents[i], ents[(i + 1) % {n}], ("y", "u"), time_shifted=True, initial_data={{"y": 0.0}})
t0 = time.perf_counter()
world.run(until={steps}, print_progress=False)
print({steps} / (time.perf_counter() - t0))
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900)
    if res.returncode:
        raise RuntimeError(res.stderr[-2000:])
    return float(res.stdout.split()[-1])


RUNNERS = {
    "hycosim": run_hycosim,
    "zenoh-floor": run_zenoh_floor,
    "helics-tcp": lambda n, s, w: run_helics("tcp", n, s),
    "helics-zmq": lambda n, s, w: run_helics("zmq", n, s),
    "mosaik": lambda n, s, w: run_mosaik(n, s),
}


def _median(values: list[float]) -> float:
    ordered = sorted(values)
    mid = len(ordered) // 2
    return ordered[mid] if len(ordered) % 2 else 0.5 * (ordered[mid - 1] + ordered[mid])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[2, 4, 8, 16])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--repeat", type=int, default=3, help="rounds per system and N; the median is reported")
    ap.add_argument("--systems", nargs="+", default=SYSTEMS, choices=SYSTEMS)
    ap.add_argument("--wait-strategy", default="auto", choices=["auto", "block", "yield"],
                    help="coSimulation.waitStrategy for hycosim and the Zenoh floor")
    ap.add_argument("--json", action="store_true",
                    help="one JSON object per line: system, n, steps_per_s (the median), runs")
    args = ap.parse_args()
    runs: dict[tuple[str, int], list[float]] = {(system, n): [] for n in args.n for system in args.systems}
    skipped: set[str] = set()
    for n in args.n:
        for _ in range(args.repeat):
            for system in args.systems:
                if system in skipped:
                    continue
                try:
                    runs[(system, n)].append(RUNNERS[system](n, args.steps, args.wait_strategy))
                except ImportError as exc:
                    skipped.add(system)
                    print(f"# {system}: skipped ({exc}; pip install -e '.[bench]')", file=sys.stderr)
                except Exception as exc:  # report and go on with the other systems
                    print(f"# {system} n={n}: failed:\n{str(exc).strip()[-3000:]}", file=sys.stderr)
                time.sleep(0.5)  # let sockets of the last run close
        for system in args.systems:
            if args.json:
                rates = runs[(system, n)]
                print(json.dumps({"system": system, "n": n, "steps_per_s": _median(rates) if rates else None,
                                  "runs": [round(r, 1) for r in rates]}), flush=True)
    if args.json:
        return
    results = {key: (_median(rates) if rates else None) for key, rates in runs.items()}
    print(f"median of {args.repeat} runs, macro steps/s (min–max in brackets)")
    print(f"{'system':<12}" + "".join(f"{'N=' + str(n):>24}" for n in args.n))
    for system in args.systems:
        cells = []
        for n in args.n:
            rates = runs[(system, n)]
            cells.append(f"{_median(rates):>8,.0f} [{min(rates):,.0f}–{max(rates):,.0f}]" if rates else "-")
        print(f"{system:<12}" + "".join(f"{c:>24}" for c in cells))
    print("\nratios of the medians (hycosim / other):")
    for system in args.systems:
        if system == "hycosim":
            continue
        cells = []
        for n in args.n:
            a, b = results.get(("hycosim", n)), results[(system, n)]
            cells.append(f"{a / b:>24.2f}" if a and b else f"{'-':>24}")
        print(f"{system:<12}" + "".join(cells))
    if "hycosim" in args.systems and len(args.n) > 1:
        base_n = args.n[0]
        base = results[("hycosim", base_n)]
        print("\nhycosim cost per step relative to N={}: ".format(base_n) + ", ".join(
            f"N={n}: {base / results[('hycosim', n)]:.2f}× (linear would be {n / base_n:.0f}×)"
            for n in args.n if results[("hycosim", n)] and base))


if __name__ == "__main__":
    main()
