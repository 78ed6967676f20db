"""``hycosim run FILE``: the server and every node as local processes on loopback.

The server reports progress as JSON lines on its stdout; this launcher turns them into
a progress bar, watches the node processes (one that dies early stops the run with its
own message), and always leaves the run directory behind.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from hycosim.core import signals
from hycosim.core.config import LoadedProject
from hycosim.core.folders import run_dir_for
from hycosim.core.signals import FAILED_ELSEWHERE, NODE_UNLOADABLE


def free_loopback_endpoint() -> str:
    """A Zenoh endpoint on a TCP port of 127.0.0.1 that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


@dataclass
class EmbeddedResult:
    """How ``hycosim run`` ended: its exit code, the run directory, the message for the user, each
    failed node's own words, and what went amiss without harming the records."""

    code: int
    run_dir: Path
    message: str
    node_failures: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)  # what went amiss without harming the records


_LAUNCHER_LINE = "[hycosim run]"  # what the launcher itself writes into a node's stderr file


def _tail(path: Path, lines: int = 5) -> str:
    try:
        said = [line for line in path.read_text(errors="replace").strip().splitlines()
                if not line.startswith(_LAUNCHER_LINE)]  # a process's last words, not the launcher's
    except OSError:
        return ""
    return "\n".join(said[-lines:]).strip().removeprefix("error: ")  # the CLI's prefix: the launcher adds its own


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


def _node_failure(run_dir: Path, name: str, status: int, before_start: bool = False) -> str:
    """What a node that ended with ``status`` said, or how its process died."""
    log = run_dir / f"node-{name}.stderr.txt"
    when = " before the run started" if before_start else ""
    if status < 0:
        # A crash in a model's native code (an FMU, an extension): the process said nothing of
        # its own, but the fault handler (hycosim.cli.main) wrote the stack it was at to its stderr.
        cause = _signal_name(-status)
        said = _tail(log, 3)
        return (f"its process died of {cause}{when} (the Python stack at that moment: {log})"
                + (f"; its last words:\n{said}" if said else ""))
    said = _tail(log)
    if status == 0:
        return f"its process ended{when} with exit status 0" + (f": {said}" if said else "")
    return said or f"exit status {status}{when}"


def _record_failure(run_dir: Path, message: str) -> None:
    """The launcher stopped the server (with SIGINT) because a node failed: its meta.json says
    it was interrupted; say why instead, so that the run directory tells what the user was told."""
    path = run_dir / "meta.json"
    try:
        meta = json.loads(path.read_text())
        if meta.get("status") != "interrupted":
            return
        meta.update(status="failed", reason=message)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(meta, indent=2))
        tmp.replace(path)
    except (OSError, ValueError):
        pass  # the message still reaches the user


def run_progress(loaded: LoadedProject, console: Console, show: bool) -> tuple[Progress, Callable[[dict], None]]:
    """The progress bar of a run (time, steps/s, mode), and the function that moves it to a
    progress report (the relay's Progress as a dict)."""
    start = loaded.project.coSimulation.startTime
    bar = Progress(TextColumn("[bold]{task.description}"), BarColumn(),
                   TextColumn("t={task.fields[t]:.3f}/{task.total:.3f} s"),
                   TextColumn("{task.fields[rate]:.0f} steps/s"), TextColumn("mode={task.fields[mode]}"),
                   TimeElapsedColumn(), console=console, disable=not show)
    task = bar.add_task(loaded.name, total=loaded.project.coSimulation.stopTime - start, t=0.0, rate=0.0, mode="free")

    def update(p: dict) -> None:
        bar.update(task, completed=p["t"] - start, t=p["t"] - start, rate=p["steps_per_s"], mode=p["mode"])

    return bar, update


def _pump(stream, sink: queue.Queue) -> None:
    for line in stream:
        sink.put(line)
    sink.put(None)


def run_embedded(loaded: LoadedProject, config_path: Path, *, listen: str | None = None,
                 runs_dir: Path = Path("runs"), console: Console | None = None,
                 show_progress: bool = True, restarts: int = 3, resume: Path | None = None,
                 dashboard_port: int | None = None, scenario_file: Path | None = None,
                 record: str | None = None) -> EmbeddedResult:
    """Run the server and every node on loopback. A node process that dies before the run starts,
    or with checkpoints (coSimulation.checkpointEvery) during it, is started again, at most
    ``restarts`` times per node (before the start: not after two alike failures);
    ``resume``: go on with the run in that directory from its last checkpoint;
    ``dashboard_port``: serve the dashboard of the run on that port of 127.0.0.1 while it runs;
    ``scenario_file``: the server takes its overrides in time (``--scenario``); ``record``: the
    tables' format (``--record``)."""
    console = console or Console(stderr=True)
    endpoint = listen or free_loopback_endpoint()
    run_dir = resume if resume is not None else run_dir_for(runs_dir, loaded.name)
    # -P: "python -m" would put the working directory first on the children's import path,
    # so a user's grp.py or zenoh.py there would replace the library in every node.
    cmd = [sys.executable, "-P", "-m", "hycosim"]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    mode = "a" if resume is not None else "w"
    board = None
    if dashboard_port is not None:
        # Started first, and serving before the run starts: its imports (a web stack, Zenoh)
        # would otherwise take CPU from the run's first seconds, and the page shows step 0.
        board = _start_dashboard([*cmd, "dashboard", endpoint, "--project", loaded.name, "--port",
                                  str(dashboard_port), "--retry", "0.25"], run_dir, env, console)
    server = subprocess.Popen([*cmd, "server", str(config_path), "--listen", endpoint, "--progress-jsonl",
                               *(["--scenario", str(scenario_file)] if scenario_file is not None else []),
                               *(["--record", record] if record is not None else []),
                               *(["--resume", str(run_dir)] if resume is not None else ["--run-dir", str(run_dir)])],
                              stdout=subprocess.PIPE, stderr=open(run_dir / "server.stderr.txt", mode),
                              text=True, env=env)

    def start_node(name: str, mode: str) -> subprocess.Popen:
        err = open(run_dir / f"node-{name}.stderr.txt", mode)
        return subprocess.Popen([*cmd, "node", name, str(config_path), "--connect", endpoint,
                                 "--log-file", str(run_dir / f"node-{name}.log.jsonl")],
                                stdout=err, stderr=subprocess.STDOUT, env=env)

    nodes: dict[str, subprocess.Popen] = {}
    for spec in loaded.project.nodeLists:
        try:
            nodes[spec.nodeName] = start_node(spec.nodeName, mode)
        except OSError as exc:
            # The run's folder went (or became unwritable) after the server started: stop what
            # was started rather than leave the server waiting for nodes until its attach timeout.
            _stop_dashboard(board)
            return _abandon(server, nodes, run_dir, _unstartable(spec.nodeName, run_dir, exc))
    restartable = loaded.project.coSimulation.checkpointEvery is not None
    restarted: dict[str, int] = {}
    last_cause: dict[str, str] = {}  # node → why its last process before the start ended
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=_pump, args=(server.stdout, lines), daemon=True).start()
    code, message, failures = None, "", {}
    user_stopped = server_stopped = started = False
    progress, show = run_progress(loaded, console, show_progress)
    try:
        with progress:
            while code is None:
                try:
                    line = lines.get(timeout=0.2)
                except queue.Empty:
                    line = ""
                if line is None:
                    break
                if line.strip():
                    try:
                        msg = json.loads(line)
                    except json.JSONDecodeError:
                        continue
                    if "progress" in msg:
                        started = True
                        show(msg["progress"])
                    elif "done" in msg:
                        code, message = msg["done"], msg["message"]
                for name, proc in list(nodes.items()):
                    # Before the run starts no node has a reason to end (exit status 0 included),
                    # unless the launcher stopped the server for another node's failure. A node
                    # the server stopped (FAILED_ELSEWHERE) did not fail, at any time: the server
                    # says why it stopped (a Dask worker stops a trial's server alone, and the
                    # server may stop the run before this loop has read that it started).
                    if name not in failures and proc.poll() is not None and proc.returncode != FAILED_ELSEWHERE and (
                            proc.returncode != 0 or not (started or server_stopped)):
                        cause = _node_failure(run_dir, name, proc.returncode, before_start=not started)
                        # Before the start nothing of the node's is lost: its new process attaches as
                        # the first did. During the run the server restores it from the last
                        # checkpoint once the new process says HELLO. Not started again: a process
                        # that fails before the start as the one before it did (a broken model), one
                        # whose server is gone.
                        again = (restarted.get(name, 0) < restarts and code is None and not server_stopped
                                 and proc.returncode != NODE_UNLOADABLE
                                 and server.poll() is None
                                 and (restartable if started else last_cause.get(name) != cause))
                        if again:
                            restarted[name] = restarted.get(name, 0) + 1
                            last_cause[name] = cause
                            try:
                                with open(run_dir / f"node-{name}.stderr.txt", "a") as log:
                                    log.write(f"\n{_LAUNCHER_LINE} started again ({restarted[name]} of {restarts}): "
                                              f"{cause}\n")
                                nodes[name] = start_node(name, "a")
                                continue
                            except OSError as exc:
                                cause = f"{cause}; {_unstartable(name, run_dir, exc)}"
                        failures[name] = cause + (f" (after {restarted[name]} restart(s))" if name in restarted else "")
                # A node failed: stop the server, once it has started its records (a server
                # stopped while it still imports would leave no meta.json to say what happened).
                if failures and not server_stopped and server.poll() is None and (
                        (run_dir / "meta.json").exists() or not run_dir.is_dir()):
                    server.send_signal(signal.SIGINT)
                    server_stopped = True
    except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM or SIGHUP: the server is told the same
        server.send_signal(signals.signal_of(exc))
        code, message = signals.exit_code(exc), signals.describe(exc)
        user_stopped = True
    try:
        return _shut_down(server, nodes, run_dir, code, message, failures, user_stopped)
    except KeyboardInterrupt:
        # Ctrl-C again while waiting for the processes to end: stop waiting for the nodes. The
        # server still writes its records (it ignores Ctrl-C for the seconds that takes).
        for proc in nodes.values():
            if proc.poll() is None:
                proc.kill()
        try:
            server.wait(timeout=10)
        except subprocess.TimeoutExpired:
            server.kill()
        for proc in (server, *nodes.values()):
            proc.wait()
        return EmbeddedResult(code if code and code >= 128 else 130, run_dir, message or "interrupted by Ctrl-C", {})
    finally:
        _stop_dashboard(board)


def _unstartable(name: str, run_dir: Path, exc: OSError) -> str:
    """Why node ``name``'s process could not be started: its log file in the run's folder."""
    gone = "; the run's folder was moved or removed" if not run_dir.is_dir() else ""
    return f"node {name!r} could not be started: its log file {exc.filename} cannot be opened ({exc.strerror}{gone})"


def _abandon(server: subprocess.Popen, nodes: dict[str, subprocess.Popen], run_dir: Path,
             message: str) -> EmbeddedResult:
    """A run that cannot go on before it started: the server and the nodes started so far are
    stopped (each wait bounded), and the run ends with ``message``."""
    # Stopped once it has started its records (where it still can), so that its meta.json
    # is there to say why the run ended.
    deadline = time.monotonic() + 10.0
    while (server.poll() is None and run_dir.is_dir() and not (run_dir / "meta.json").exists()
           and time.monotonic() < deadline):
        time.sleep(0.05)
    if server.poll() is None:
        server.send_signal(signal.SIGINT)
    result = _shut_down(server, nodes, run_dir, 3, message, {}, False)
    _record_failure(run_dir, message)
    return result


def _start_dashboard(command: list[str], run_dir: Path, env: dict[str, str], console: Console) -> subprocess.Popen:
    """Start the dashboard process and say where its page is (it connects to the server by itself)."""
    board = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=open(run_dir / "dashboard.stderr.txt", "w"),
                             text=True, env=env)
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=_pump, args=(board.stdout, lines), daemon=True).start()
    try:
        line = lines.get(timeout=30)
    except queue.Empty:
        line = None
    if line and line.startswith("dashboard: "):
        console.print(f"{line.strip()} (open it in a browser; it closes with the run)", highlight=False)
    else:
        console.print(f"[yellow]warning:[/yellow] the dashboard did not start: "
                      f"{_tail(run_dir / 'dashboard.stderr.txt') or 'no word from it'}", highlight=False)
    return board


def _stop_dashboard(board: subprocess.Popen | None) -> None:
    if board is None or board.poll() is not None:
        return
    board.terminate()
    try:
        board.wait(timeout=5)
    except subprocess.TimeoutExpired:
        board.kill()
        board.wait()


def _shut_down(server: subprocess.Popen, nodes: dict[str, subprocess.Popen], run_dir: Path, code: int | None,
               message: str, failures: dict[str, str], user_stopped: bool) -> EmbeddedResult:
    """Wait for the server and the nodes to end, stop the ones that do not, and say how the run went."""
    try:
        server.wait(timeout=30)
    except subprocess.TimeoutExpired:
        server.kill()
    if code is None:
        code, message = (server.returncode or 3), _tail(run_dir / "server.stderr.txt") or "the server exited"
        if server.returncode < 0:
            code, message = 3, f"the server's process died of {_signal_name(-server.returncode)}"
        if (run_dir / "checkpoints").is_dir():
            message += f"; the run can go on from its last checkpoint: hycosim run FILE --resume {run_dir}"
    # After a completed run the nodes have their STOP and leave by themselves. After a failed
    # one, a node may still wait for a START or a step that will not come, until its own
    # timeout: it is interrupted after a short grace, and its complaint is not a failure.
    grace = 15.0 if code == 0 else 2.0
    deadline = time.monotonic() + grace
    interrupted = set()
    warnings: list[str] = []
    for name, proc in nodes.items():
        try:
            proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGINT if code else signal.SIGKILL)
            interrupted.add(name)
    deadline = time.monotonic() + 10.0  # one bound for all: a node stuck in a blocking call may not see SIGINT
    for name, proc in nodes.items():
        try:
            proc.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if code == 0 and name in interrupted and name not in failures:
            # The run completed: the node had sent its last outputs, every record is whole. A
            # model slow to let go (its teardown, a thread) is the node's business, not the run's.
            warnings.append(f"node {name!r} had not exited {grace:g} s after the run completed and was killed "
                            f"(its records are complete; see {run_dir / f'node-{name}.stderr.txt'})")
            continue
        if proc.returncode not in (0, FAILED_ELSEWHERE) and name not in failures and not (code and name in interrupted):
            failures[name] = _node_failure(run_dir, name, proc.returncode)
    if user_stopped:
        # Ctrl-C in a terminal reaches every process of the group at once: whatever a node said
        # as it stopped (status 130, or an import cut short: "initialization failed") is not a
        # failure of the run the user stopped.
        failures = {}
    elif code == 130:
        failures = {n: m for n, m in failures.items() if nodes[n].returncode != 130}
    if failures and code in (0, 130):
        code = 3
        message = "; ".join(f"{n}: {m}" for n, m in failures.items())
        _record_failure(run_dir, message)
    elif failures:
        message += "".join(f"\n  node {n}: {m}" for n, m in failures.items() if m)
    return EmbeddedResult(code, run_dir, message, failures, warnings)
