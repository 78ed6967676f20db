"""Macro-step barrier throughput: hycosim against HELICS (tcp, zmq), mosaik 3 and a plain Zenoh barrier.

One workload for every system, in one run: N nodes, each its own OS process, in a ring,
one float in and out each, y = 0.5·u + 1, for 3000 macro steps; N = 2, 4, 8, 16.
Rates count macro steps per second of the stepping loop only (start-up excluded).
Processes are not pinned to cores: on 2 cores the scheduler decides, as it would for a user.
Every process of a run is started in this one's session, as a user's launcher (``hycosim run``,
a shell) starts them: where the kernel groups processes by session to schedule them (autogroup),
processes in sessions of their own were preempted twice as often (``_procs.start``).
hycosim's nodes are scheduled as its project says (``nodeScheduling``: as batch work where they
outnumber the cores), and so are the floor's; HELICS's and mosaik's processes as the system's
default.

    python benchmarks/barrier.py [--n 2 4] [--steps 3000] [--repeat 3] [--systems hycosim helics-tcp ...]
                                 [--wait-strategy auto|block|yield] [--timeout 120] [--cpu] [--json]

On a small machine one run of any system scatters by ±20 % (who shares a core with whom
is the scheduler's choice), so every system runs ``--repeat`` times, the rounds
interleaved (system after system, then again), and the table shows the median; each ratio of
hycosim's figure to another system's comes with the range of the rounds' own ratios (round i
against round i), which says how far one round's comparison strays from the medians'.
A run that fails or passes ``--timeout`` (its whole process group is killed) is reported
and left out of the median; the exit status is 1 when some system and N has no run left.

With ``--cpu``, each round also measures the CPU time a macro step costs all of a system's
processes together (user and system time, every thread), where no process polls
(``waitStrategy`` ``block``): a run of 4 × ``--steps`` less a run of ``--steps``, over
3 × ``--steps``, so that start-up and shutdown cancel out. On a machine with fewer cores
than processes the rate depends on how the scheduler shares the cores; the CPU a step costs
does much less. The times come from the rusage of reaped processes: this process is made
their subreaper, so that a process a run leaves to end by itself (a master that does not wait
for its simulators) is reaped and counted here too, and before each run all are reaped.
Two more tables split that cost: the coordinating process's own (hycosim's and the floor's
server, HELICS's broker, mosaik's world; read from its /proc stat once it has exited, before
it is reaped) and every other process's (the rest).

HELICS and mosaik come from the optional extra: pip install -e '.[bench]'.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import _table
from _procs import descendants, free_port, own_cpu_at_exit, run, start, stop_all, wait_all

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
SYSTEMS = ["hycosim", "zenoh-floor", "helics-tcp", "helics-zmq", "mosaik"]


def ring_config(n: int, steps: int, path: Path, wait_strategy: str = "auto") -> Path:
    """A ring of ``n`` gain nodes (each y = 0.5·u + 1 on its predecessor's y), ``steps`` macro steps,
    written to ``path``; its path."""
    nodes = [{"nodeName": f"n{i}", "UID": i + 1, "model": "gain", "parameters": {"k": 0.5, "b": 1.0},
              "input": ["u"], "output": ["y"]} for i in range(n)]
    links = [{"from": f"n{i}.y", "to": f"n{(i + 1) % n}.u"} for i in range(n)]
    doc = {"projectName": f"ring{n}", "serverIP": f"127.0.0.1:{free_port()}", "nodeNum": n, "nodeLists": nodes,
           "linkNum": n, "linkLists": links,
           "coSimulation": {"stepSize": 1.0, "stopTime": float(steps), "stepTimeout": 30.0,
                            "waitStrategy": wait_strategy}}
    path.write_text(json.dumps(doc))
    return path


def run_hycosim(n: int, steps: int, wait_strategy: str, timeout: float) -> float:
    """The ring's steps/s as ``hycosim run`` runs it."""
    with tempfile.TemporaryDirectory() as tmp:
        cfg = ring_config(n, steps, Path(tmp) / "ring.json", wait_strategy)
        res = run([sys.executable, "-m", "hycosim", "run", str(cfg), "--runs-dir", tmp, "--no-progress"],
                  timeout, own_session=False, cwd=REPO)
        if res.returncode:
            logs = "".join(f"--- {p.name}\n{p.read_text()[-800:]}" for p in Path(tmp).glob("ring*/*.stderr.txt"))
            raise RuntimeError(res.stderr + logs)
        return _rate_of(Path(tmp))


def _rate_of(runs: Path) -> float:
    """The steps/s a ring's run recorded in its meta.json under ``runs``."""
    return float(json.loads(next(runs.glob("ring*/meta.json")).read_text())["steps_per_s"])


def _start_hycosim(n: int, steps: int, wait_strategy: str, tmp: str,
                   **server_output: Any) -> tuple[subprocess.Popen, list[subprocess.Popen]]:
    """The ring as its processes alone, started as the floor's and HELICS's are: ``hycosim
    server`` and a ``hycosim node`` each, without the ``hycosim run`` launcher, whose progress
    bar and closing report (it reads the run's timing back) are no part of a macro step.
    ``server_output``: where the server's stdout and stderr go (Popen's arguments)."""
    cfg = ring_config(n, steps, Path(tmp) / "ring.json", wait_strategy)
    py = [sys.executable, "-P", "-m", "hycosim"]
    server = start([*py, "server", str(cfg), "--runs-dir", tmp], own_session=False, cwd=REPO, text=True,
                   **server_output)
    nodes = [start([*py, "node", f"n{i}", str(cfg)], own_session=False, cwd=REPO, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL) for i in range(n)]
    return server, nodes


def run_hycosim_processes(n: int, steps: int, wait_strategy: str, timeout: float) -> float:
    """The ring's steps/s as its processes alone (:func:`_start_hycosim`)."""
    with tempfile.TemporaryDirectory() as tmp:
        server, nodes = _start_hycosim(n, steps, wait_strategy, tmp, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            out, err = wait_all(server, nodes, timeout)
        except subprocess.TimeoutExpired:
            raise RuntimeError(f"timed out after {timeout:g} s (--timeout): hycosim with {n} nodes") from None
        if server.returncode:
            raise RuntimeError(f"hycosim server exited {server.returncode}: {err[-800:]}")
        return _rate_of(Path(tmp))


def _floor_command(n: int, steps: int, wait_strategy: str) -> list[str]:
    """The floor's server, which starts its nodes and prints its rate."""
    return [sys.executable, str(HERE / "_zenoh_floor.py"), "server", f"tcp/127.0.0.1:{free_port()}", str(n),
            str(steps), wait_strategy]


def run_zenoh_floor(n: int, steps: int, wait_strategy: str, timeout: float) -> float:
    """The floor's steps/s for ``n`` nodes."""
    res = run(_floor_command(n, steps, wait_strategy), timeout, own_session=False)
    if res.returncode:
        raise RuntimeError(res.stderr)
    return float(res.stdout.split()[-1])


def _helics_commands(core: str, n: int, steps: int) -> tuple[list[str], list[list[str]]]:
    """HELICS's broker and its ``n`` federates (the first prints the rate), on a free port."""
    port, script = str(free_port()), str(HERE / "_helics_fed.py")
    return ([sys.executable, script, "broker", core, str(n), port],
            [[sys.executable, script, "fed", core, str(n), str(i), str(steps), port] for i in range(n)])


def run_helics(core: str, n: int, steps: int, timeout: float) -> float:
    """HELICS's steps/s for ``n`` federates over ``core`` (tcp, zmq)."""
    broker_command, fed_commands = _helics_commands(core, n, steps)
    broker = start(broker_command, own_session=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    feds = [start(command, own_session=False, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
            for command in fed_commands]
    try:  # one limit for the whole run, as for the other systems
        out = wait_all(feds[0], [*feds[1:], broker], timeout)[0]
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"timed out after {timeout:g} s (--timeout): HELICS {core} with {n} federates") from None
    return _figure(out)


def _figure(out: str) -> float:
    """The steps/s a federate printed: HELICS may log lines of its own to stdout around it."""
    for line in reversed(out.splitlines()):
        try:
            return float(line.split()[0])
        except (IndexError, ValueError):
            continue
    raise RuntimeError(f"no figure in the federate's output: {out[-500:]!r}")


def _mosaik_code(n: int, steps: int) -> str:
    return f"""
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


def run_mosaik(n: int, steps: int, timeout: float) -> float:
    """mosaik 3's steps/s for ``n`` simulators."""
    res = run([sys.executable, "-c", _mosaik_code(n, steps)], timeout, own_session=False)
    if res.returncode:
        raise RuntimeError(res.stderr[-2000:])
    return float(res.stdout.split()[-1])


RUNNERS = {
    "hycosim": run_hycosim,
    "zenoh-floor": run_zenoh_floor,
    "helics-tcp": lambda n, s, w, timeout: run_helics("tcp", n, s, timeout),
    "helics-zmq": lambda n, s, w, timeout: run_helics("zmq", n, s, timeout),
    "mosaik": lambda n, s, w, timeout: run_mosaik(n, s, timeout),
}


def coordinator_cpu(coordinator: subprocess.Popen, others: list[subprocess.Popen], timeout: float, what: str,
                    output: Path) -> float:
    """Wait for ``others`` and then ``coordinator`` (one ``timeout`` for all) and return the
    CPU seconds the coordinator used itself (:func:`own_cpu_at_exit`). RuntimeError naming
    ``what`` for a timeout or a process that failed (with ``output``'s tail, the coordinator's
    output); every group still running on the way out is killed."""
    deadline = time.monotonic() + timeout
    try:
        for p in others:
            p.wait(timeout=max(0.0, deadline - time.monotonic()))
        cpu = own_cpu_at_exit(coordinator, max(0.0, deadline - time.monotonic()))
        coordinator.wait()
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"timed out after {timeout:g} s (--timeout): {what}") from None
    finally:
        stop_all(coordinator, *others)
    failed = [p.returncode for p in (coordinator, *others) if p.returncode]
    if failed:
        raise RuntimeError(f"{what}: a process exited {failed[0]}: {output.read_text()[-800:]}")
    return cpu


def cpu_hycosim(n: int, steps: int, timeout: float) -> float:
    """hycosim's ring, waiting by blocking; its server's own CPU seconds."""
    with tempfile.TemporaryDirectory() as tmp:
        output = Path(tmp) / "server.txt"
        with output.open("w") as out:
            server, nodes = _start_hycosim(n, steps, "block", tmp, stdout=out, stderr=subprocess.STDOUT)
        return coordinator_cpu(server, nodes, timeout, f"hycosim with {n} nodes", output)


def cpu_zenoh_floor(n: int, steps: int, timeout: float) -> float:
    """The floor, waiting by blocking; its server's own CPU seconds (its nodes are its children)."""
    with tempfile.TemporaryDirectory() as tmp:
        output = Path(tmp) / "server.txt"
        with output.open("w") as out:
            server = start(_floor_command(n, steps, "block"), own_session=False, stdout=out, stderr=subprocess.STDOUT)
        return coordinator_cpu(server, [], timeout, f"the Zenoh floor with {n} nodes", output)


def cpu_helics(core: str, n: int, steps: int, timeout: float) -> float:
    """HELICS's ring; its broker's own CPU seconds."""
    broker_command, fed_commands = _helics_commands(core, n, steps)
    with tempfile.TemporaryDirectory() as tmp:
        output = Path(tmp) / "broker.txt"
        with output.open("w") as out:
            broker = start(broker_command, own_session=False, stdout=out, stderr=subprocess.STDOUT)
        feds = [start(command, own_session=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                for command in fed_commands]
        return coordinator_cpu(broker, feds, timeout, f"HELICS {core} with {n} federates", output)


def cpu_mosaik(n: int, steps: int, timeout: float) -> float:
    """mosaik's ring; its world's (the master's) own CPU seconds (its simulators are its children)."""
    with tempfile.TemporaryDirectory() as tmp:
        output = Path(tmp) / "world.txt"
        with output.open("w") as out:
            world = start([sys.executable, "-c", _mosaik_code(n, steps)], own_session=False, stdout=out,
                          stderr=subprocess.STDOUT)
        return coordinator_cpu(world, [], timeout, f"mosaik with {n} simulators", output)


# What one run of a system for --cpu does, waiting by blocking where the system can: the CPU
# seconds its coordinating process (the server, the broker, the world) used itself.
CPU_RUNNERS = {
    "hycosim": cpu_hycosim,
    "zenoh-floor": cpu_zenoh_floor,
    "helics-tcp": lambda n, s, timeout: cpu_helics("tcp", n, s, timeout),
    "helics-zmq": lambda n, s, timeout: cpu_helics("zmq", n, s, timeout),
    "mosaik": cpu_mosaik,
}


CPU_LENGTHS = 4  # the longer of the two runs --cpu compares, in --steps
_PR_SET_CHILD_SUBREAPER = 36  # linux/prctl.h


def become_subreaper() -> None:
    """Have the processes a run leaves behind reparented to this one rather than to init, so
    that :func:`reap` counts their CPU time (Linux)."""
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_CHILD_SUBREAPER) failed")


def reap(timeout: float = 10.0) -> None:
    """Wait (up to ``timeout`` s) until no process below this one is left, reaping each; any
    still running then is killed (and reaped, for a few seconds more), so that the next run's
    figures are its own."""
    deadline, killed = time.monotonic() + timeout, False
    while True:
        while True:
            try:
                pid, _ = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                pid = 0
            if pid == 0:
                break
        left = descendants(os.getpid())
        if not left or (killed and time.monotonic() > deadline):
            return
        if not killed and time.monotonic() > deadline:
            for pid in left:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            deadline, killed = time.monotonic() + 3.0, True
        time.sleep(0.02)


def cpu_seconds(system: str, n: int, steps: int, timeout: float) -> tuple[float, float]:
    """The CPU time (user + system) of all the processes of one run of ``system``, waiting by
    blocking, and of its coordinating process alone (:data:`CPU_RUNNERS`)."""
    reap()  # what an earlier run left is not this one's
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    try:
        coordinator = CPU_RUNNERS[system](n, steps, timeout)
    finally:
        reap()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime), coordinator


def cpu_per_step(system: str, n: int, steps: int, timeout: float) -> tuple[float, float]:
    """µs of CPU a macro step costs all of a system's processes, and its coordinating process
    alone: a run of CPU_LENGTHS × ``steps`` less a run of ``steps``, over the steps between them."""
    short, short_coordinator = cpu_seconds(system, n, steps, timeout)
    long, long_coordinator = cpu_seconds(system, n, CPU_LENGTHS * steps, timeout)
    between = (CPU_LENGTHS - 1) * steps
    return (long - short) / between * 1e6, (long_coordinator - short_coordinator) / between * 1e6


def _median(values: list[float]) -> float:
    ordered = sorted(values)
    mid = len(ordered) // 2
    return ordered[mid] if len(ordered) % 2 else 0.5 * (ordered[mid - 1] + ordered[mid])


def main() -> None:
    """Measure the systems' rates (and with ``--cpu`` their CPU a step) in interleaved rounds and print
    the medians; ``--json`` a line per system and N, ``--table`` the manual's tables."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[2, 4, 8, 16])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--repeat", type=int, default=3, help="rounds per system and N; the median is reported")
    ap.add_argument("--systems", nargs="+", default=SYSTEMS, choices=SYSTEMS)
    ap.add_argument("--wait-strategy", default="auto", choices=["auto", "block", "yield"],
                    help="coSimulation.waitStrategy for hycosim and the Zenoh floor")
    ap.add_argument("--json", action="store_true",
                    help="one JSON object per line: system, n, steps_per_s (the median), runs")
    ap.add_argument("--timeout", type=float, default=120.0,
                    help="seconds one run of one system may take; a run past it is reported as failed "
                         "and left out of the median (a HELICS zmq run once hung here for good)")
    ap.add_argument("--cpu", action="store_true",
                    help="also measure the CPU a macro step costs all of a system's processes, "
                         f"waiting by blocking (two more runs a round: --steps and {CPU_LENGTHS} x --steps)")
    _table.add_argument(ap)
    args = ap.parse_args()
    runs: dict[tuple[str, int], list[float]] = {(system, n): [] for n in args.n for system in args.systems}
    cpu: dict[tuple[str, int], list[float]] = {key: [] for key in runs}
    coordinator: dict[tuple[str, int], list[float]] = {key: [] for key in runs}
    skipped: set[str] = set()
    if args.cpu:
        become_subreaper()
    for n in args.n:
        for _ in range(args.repeat):
            for system in args.systems:
                if system in skipped:
                    continue
                try:
                    runs[(system, n)].append(RUNNERS[system](n, args.steps, args.wait_strategy, args.timeout))
                    if args.cpu:
                        time.sleep(0.5)
                        total, own = cpu_per_step(system, n, args.steps, args.timeout)
                        cpu[(system, n)].append(total)
                        coordinator[(system, n)].append(own)
                except ImportError as exc:
                    skipped.add(system)
                    print(f"# {system}: skipped ({exc}; pip install -e '.[bench]')", file=sys.stderr)
                except Exception as exc:  # report and go on with the other systems
                    print(f"# {system} n={n}: failed:\n{str(exc).strip()[-3000:]}", file=sys.stderr)
                time.sleep(0.5)  # let sockets of the last run close
        for system in args.systems:
            if args.json:
                rates, costs = runs[(system, n)], cpu[(system, n)]
                line = {"system": system, "n": n, "steps_per_s": _median(rates) if rates else None,
                        "runs": [round(r, 1) for r in rates]}
                if args.cpu:
                    own, rest = coordinator[(system, n)], _rest(cpu, coordinator)[(system, n)]
                    line |= {"cpu_us_per_step": _median(costs) if costs else None,
                             "cpu_runs": [round(c, 1) for c in costs],
                             "cpu_coordinator_us_per_step": _median(own) if own else None,
                             "cpu_coordinator_runs": [round(c, 1) for c in own],
                             "cpu_rest_us_per_step": _median(rest) if rest else None}
                print(json.dumps(line), flush=True)
    empty = sorted(f"{system} N={n}" for (system, n), rates in runs.items() if not rates and system not in skipped)
    tables = [_manual_table(args, runs, skipped, _rate_caption(args))]
    if args.cpu:
        tables += [_manual_table(args, cpu, skipped, _cpu_caption(args)),
                   _manual_table(args, coordinator, skipped, _COORDINATOR_CAPTION),
                   _manual_table(args, _rest(cpu, coordinator), skipped, _REST_CAPTION)]
    _table.write(args.table, *tables)
    if not args.json:
        _print_table(args, runs, skipped)
        if args.cpu:
            for table in tables[1:]:
                print("\n" + "\n".join(table.markdown()))
    if empty:
        print(f"# no run completed for {', '.join(empty)}", file=sys.stderr)
        sys.exit(1)


def round_ratios(ours: list[float], theirs: list[float], rounds: int) -> tuple[float, float] | None:
    """The lowest and highest of the rounds' own ratios (round i's ``ours`` over round i's
    ``theirs``): how far one round's comparison strays from the medians'. None where there are
    fewer than two rounds or a run of either failed: a list then lacks a round, and position i
    of the one may be another round than position i of the other."""
    if rounds < 2 or len(ours) != rounds or len(theirs) != rounds or not all(theirs):
        return None
    ratios = [a / b for a, b in zip(ours, theirs)]
    return min(ratios), max(ratios)


def _ratio_cell(ours: list[float], theirs: list[float], rounds: int) -> str | None:
    """The ratio of the medians, with the rounds' own ratios' range in brackets where they pair."""
    median = _table.ratio(_median(ours) if ours else None, _median(theirs) if theirs else None)
    spread = round_ratios(ours, theirs, rounds)
    return median if median is None or spread is None else f"{median} ({spread[0]:.2f}–{spread[1]:.2f})"


def _manual_table(args: argparse.Namespace, figures: dict[tuple[str, int], list[float]], skipped: set[str],
                  caption: str) -> _table.Table:
    """The medians of ``figures`` (rates, or CPU a step) by N and system, each with its lowest
    and highest round in brackets, and hycosim's ratio to each other (the ratio of the medians,
    the rounds' own ratios' range in brackets)."""
    systems = [s for s in args.systems if s not in skipped]
    others = [s for s in systems if s != "hycosim"] if "hycosim" in systems else []
    header = ["N", *systems, *(f"hycosim / {s}" for s in others)]
    rows = [[n, *(_median_cell(figures[(s, n)]) for s in systems),
             *(_ratio_cell(figures[("hycosim", n)], figures[(s, n)], args.repeat) for s in others)] for n in args.n]
    after = ""
    if args.repeat > 1:
        after = "A figure is the median of its rounds; in brackets, the lowest and highest round."
        if others:
            after += (" A ratio is that of the medians; in brackets, the lowest and highest of the rounds' "
                      "own ratios (a round's hycosim against the same round's other).")
    return _table.Table(caption, header, rows, after)


def _median_cell(values: list[float]) -> str | None:
    """A system's median, with its lowest and highest round in brackets where it has more than
    one: a system whose rounds spread widely moves every ratio to it."""
    median = _table.rate(_median(values) if values else None)
    if median is None or len(values) < 2:
        return median
    return f"{median} ({_table.rate(min(values))}–{_table.rate(max(values))})"


def _rest(cpu: dict[tuple[str, int], list[float]],
          coordinator: dict[tuple[str, int], list[float]]) -> dict[tuple[str, int], list[float]]:
    """Per round, the CPU a step of every process but the coordinating one."""
    return {key: [total - own for total, own in zip(totals, coordinator[key])] for key, totals in cpu.items()}


_COORDINATOR_CAPTION = ("Of which the coordinating process alone (hycosim's and the floor's server, HELICS's "
                        "broker, mosaik's world), µs a macro step, medians:")
_REST_CAPTION = "Of which every other process (the nodes, federates, simulators), µs a macro step, medians:"


def _rate_caption(args: argparse.Namespace) -> str:
    return f"Macro steps/s, medians of {args.repeat} interleaved rounds of {args.steps:,} steps:"


def _cpu_caption(args: argparse.Namespace) -> str:
    return (f"CPU µs a macro step costs all of a system's processes, waiting by blocking (a run of "
            f"{CPU_LENGTHS * args.steps:,} steps less one of {args.steps:,}), medians of {args.repeat} rounds:")


def _print_table(args: argparse.Namespace, runs: dict[tuple[str, int], list[float]], skipped: set[str]) -> None:
    results = {key: (_median(rates) if rates else None) for key, rates in runs.items()}
    print(f"median of {args.repeat} runs, macro steps/s (min–max in brackets)")
    print(f"{'system':<12}" + "".join(f"{'N=' + str(n):>24}" for n in args.n))
    for system in args.systems:
        cells = []
        for n in args.n:
            rates = runs[(system, n)]
            cells.append(f"{_median(rates):>8,.0f} [{min(rates):,.0f}–{max(rates):,.0f}]" if rates else "-")
        print(f"{system:<12}" + "".join(f"{c:>24}" for c in cells))
    short = [f"{system} N={n}: {len(rates)} of {args.repeat}" for (system, n), rates in runs.items()
             if len(rates) < args.repeat and system not in skipped]
    if short:
        print("runs that failed are left out (see above): " + "; ".join(short))
    print("\nratios of the medians (hycosim / other; the rounds' own ratios' range in brackets):")
    for system in args.systems:
        if system == "hycosim":
            continue
        cells = []
        for n in args.n:
            cell = _ratio_cell(runs.get(("hycosim", n), []), runs[(system, n)], args.repeat)
            cells.append(f"{cell or '-':>24}")
        print(f"{system:<12}" + "".join(cells))
    if "hycosim" in args.systems and len(args.n) > 1:
        base_n = args.n[0]
        base = results[("hycosim", base_n)]
        print("\nhycosim cost per step relative to N={}: ".format(base_n) + ", ".join(
            f"N={n}: {base / results[('hycosim', n)]:.2f}× (linear would be {n / base_n:.0f}×)"
            for n in args.n if results[("hycosim", n)] and base))


if __name__ == "__main__":
    main()
