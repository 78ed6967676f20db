"""Memory: peak resident set of hycosim's server and nodes, against a bare Zenoh barrier in the same run.

One workload for both systems: N gains in a ring, each its own process (as barrier.py),
run for S and then 10·S macro steps. For each kind of process (the server, the nodes) it
reports the peak resident set (the kernel's VmHWM, sampled until the process ends) of
hycosim and of the plain Zenoh floor (same Python, zenoh, msgpack and inbox; no config
checking, routing, coordinator or recording), and two ratios:

* hycosim / floor per kind, on the long run: what hycosim's code and imports cost over the
  transport they share;
* long / short run per kind: growth with run length. Recording streams to disk and every
  buffer is bounded, so the goal is 1.0 (at most 1.05: allocator noise). The same for
  reading the run back (``hycosim report`` and ``plot`` on the run directory): both stream.

    python benchmarks/memory.py [--n 4] [--steps 2000] [--json] [--timeout 120]

With ``--json`` it prints one object per measurement (``system``, ``process``, ``steps``,
``peak_rss_mib``) and a last one with the ratios (``growth``, ``vs_floor``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import _table
from _procs import children, free_port, kill_group, start
from barrier import ring_config

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
SAMPLE_EVERY_S = 0.02


def _peak_rss_and_argv(pid: int) -> tuple[float, list[str]] | None:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except OSError:
        return None
    if not any(argv):
        # The process let go of its memory (exiting) between the two reads: its status
        # still had VmHWM, but this reading names nobody. The previous one stands.
        return None
    for line in status.splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0, [a.decode(errors="replace") for a in argv if a]
    return None


def peak_rss_by_process(cmd: list[str], timeout: float) -> dict[int, tuple[float, list[str]]]:
    """Run ``cmd``; return every process of its tree with its peak RSS (MiB) and argv."""
    proc = start(cmd, cwd=REPO, stdout=open(os.devnull, "w"), stderr=open(os.devnull, "w"))
    seen: dict[int, tuple[float, list[str]]] = {}
    deadline = time.monotonic() + timeout
    try:
        while proc.poll() is None:
            if time.monotonic() > deadline:
                raise RuntimeError(f"timed out after {timeout:g} s (--timeout): {' '.join(cmd[:4])} ...")
            kids, todo = children(), [proc.pid]
            while todo:
                pid = todo.pop()
                todo.extend(kids.get(pid, []))
                got = _peak_rss_and_argv(pid)
                if got is not None:  # VmHWM only grows: the last reading is the peak so far
                    seen[pid] = got
            time.sleep(SAMPLE_EVERY_S)
    finally:
        if proc.poll() is None:
            kill_group(proc)
            proc.wait()
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd[:4])} ... exited with status {proc.returncode}")
    return seen


def _kind(argv: list[str]) -> str | None:
    """'server' or 'node' for ``python [options] -m hycosim server|node …`` and ``_zenoh_floor.py server|node …``."""
    if "-m" in argv and argv[argv.index("-m") + 1:argv.index("-m") + 2] == ["hycosim"]:
        word = argv[argv.index("-m") + 2] if len(argv) > argv.index("-m") + 2 else ""
    elif len(argv) > 2 and argv[1].endswith("_zenoh_floor.py"):
        word = argv[2]
    else:
        return None
    return word if word in ("server", "node") else None


def measure(system: str, n: int, steps: int, timeout: float) -> dict[str, float]:
    """Peak RSS (MiB) of the server and of the largest node, for one run of ``system``."""
    with tempfile.TemporaryDirectory() as tmp:
        if system == "hycosim":
            cfg = ring_config(n, steps, Path(tmp) / "ring.json")
            cmd = [sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", tmp, "--no-progress"]
        else:
            cmd = [sys.executable, str(HERE / "_zenoh_floor.py"), "server", f"tcp/127.0.0.1:{free_port()}",
                   str(n), str(steps), "auto"]
        peaks: dict[str, float] = {}
        for rss, argv in peak_rss_by_process(cmd, timeout).values():
            kind = _kind(argv)
            if kind is not None:
                peaks[kind] = max(peaks.get(kind, 0.0), rss)
        if system == "hycosim":
            # Reading the run back: report and plot stream the run's files, so their peak
            # should not grow with its length either (plot keeps 8 bytes per drawn value).
            run_dir = next(Path(tmp).glob("ring*-*"))
            for kind, args in (("report", ["report", str(run_dir)]),
                               ("plot", ["plot", str(run_dir), "-o", str(Path(tmp) / "plot.png")])):
                found = peak_rss_by_process([sys.executable, "-m", "hycosim", *args], timeout).values()
                peaks[kind] = max(rss for rss, _ in found)
    if {"server", "node"} - set(peaks):
        raise RuntimeError(f"{system}: found no {' or '.join({'server', 'node'} - set(peaks))} process to measure")
    return peaks


def main() -> None:
    """Measure the peak resident sets of a short and a long run of hycosim and of the floor, and print
    them and their growth (``--json``: one object a line)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=4, help="nodes in the ring")
    ap.add_argument("--steps", type=int, default=2000, help="macro steps of the short run; the long run has 10×")
    ap.add_argument("--json", action="store_true")
    _table.add_argument(ap)
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds one run may take")
    args = ap.parse_args()
    lengths = (args.steps, 10 * args.steps)
    peaks = {(system, steps): measure(system, args.n, steps, args.timeout)
             for steps in lengths for system in ("hycosim", "zenoh-floor")}
    growth = {f"{system} {kind}": peaks[(system, lengths[1])][kind] / peaks[(system, lengths[0])][kind]
              for system in ("hycosim", "zenoh-floor") for kind in peaks[(system, lengths[0])]}
    vs_floor = {kind: peaks[("hycosim", lengths[1])][kind] / peaks[("zenoh-floor", lengths[1])][kind]
                for kind in ("server", "node")}
    _table.write(args.table, _table.Table(
        f"Peak resident set, MiB, a ring of {args.n} (the largest node), after {lengths[0]:,} and {lengths[1]:,} steps:",
        ["process", f"hycosim, {lengths[0]:,} steps", f"hycosim, {lengths[1]:,} steps", "growth",
         "bare Zenoh barrier", "hycosim / bare"],
        [[kind, f"{peaks[('hycosim', lengths[0])][kind]:.1f}", f"{peaks[('hycosim', lengths[1])][kind]:.1f}",
          f"{growth[f'hycosim {kind}']:.3f}",
          f"{peaks[('zenoh-floor', lengths[1])][kind]:.1f}" if kind in vs_floor else None,
          f"{vs_floor[kind]:.2f}" if kind in vs_floor else None]
         for kind in ("server", "node", "report", "plot") if kind in peaks[("hycosim", lengths[0])]]))
    if args.json:
        for (system, steps), by_kind in peaks.items():
            for kind, rss in by_kind.items():
                print(json.dumps({"system": system, "process": kind, "steps": steps, "peak_rss_mib": round(rss, 1)}))
        print(json.dumps({"growth": {k: round(v, 3) for k, v in growth.items()},
                          "vs_floor": {k: round(v, 2) for k, v in vs_floor.items()}}))
        return
    print(f"peak resident set, MiB (ring of {args.n}; the largest node)")
    print(f"{'':<22}{'steps=' + str(lengths[0]):>14}{'steps=' + str(lengths[1]):>14}{'growth':>10}")
    for system in ("hycosim", "zenoh-floor"):
        for kind in peaks[(system, lengths[0])]:
            short, long = peaks[(system, lengths[0])][kind], peaks[(system, lengths[1])][kind]
            print(f"{system + ' ' + kind:<22}{short:>14.1f}{long:>14.1f}{long / short:>10.3f}")
    print("hycosim / floor: " + ", ".join(f"{kind} {ratio:.2f}×" for kind, ratio in vs_floor.items()))


if __name__ == "__main__":
    main()
