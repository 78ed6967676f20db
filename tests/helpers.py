"""Shared test helpers: project files, free loopback endpoints, real processes."""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
HYCOSIM = [sys.executable, "-m", "hycosim"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_endpoint() -> str:
    return f"tcp/127.0.0.1:{free_port()}"


def write_project(path: Path, nodes: list[dict], links: list[dict] | None = None, events: list[dict] | None = None,
                  cosim: dict | None = None, name: str = "t", **extra: Any) -> Path:
    links = links or []
    doc = {"projectName": name, "serverIP": free_endpoint(), "nodeNum": len(nodes), "nodeLists": nodes,
           "linkNum": len(links), "linkLists": links, **extra}
    if cosim is not None:
        doc["coSimulation"] = cosim
    if events:
        doc["events"] = events
    path.write_text(json.dumps(doc, indent=1))
    return path


def env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")


def hycosim(*args: str, timeout: float = 120, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*HYCOSIM, *args], capture_output=True, text=True, timeout=timeout, env=env(),
                          cwd=cwd or REPO)


def spawn(*args: str, **kw: Any) -> subprocess.Popen:
    return subprocess.Popen([*HYCOSIM, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env(), cwd=REPO, **kw)


def reap(*procs: subprocess.Popen) -> None:
    """Kill whichever of the processes is still running (a test's ``finally``)."""
    for p in procs:
        if p.poll() is None:
            p.kill()


def run_project(cfg: Path, runs: Path, timeout: float = 120) -> Path:
    """``hycosim run`` the project; assert success and return its run directory."""
    res = hycosim("run", str(cfg), "--runs-dir", str(runs), "--no-progress", timeout=timeout)
    assert res.returncode == 0, f"run failed ({res.returncode}):\n{res.stdout}\n{res.stderr}"
    dirs = sorted(runs.iterdir())
    assert len(dirs) == 1
    return dirs[0]


def read_rows(run_dir: Path, name: str = "values.csv") -> list[dict[str, str]]:
    with open(run_dir / name, newline="") as f:
        return list(csv.DictReader(f))


def column(rows: list[dict[str, str]], key: str) -> list[float]:
    return [float(r[key]) for r in rows]


def meta(run_dir: Path) -> dict[str, Any]:
    return json.loads((run_dir / "meta.json").read_text())


def wait_for(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def pids(pattern: str) -> list[int]:
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                cmd = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except OSError:
                continue
            if pattern in cmd:
                found.append(int(entry))
    return found


def descendants(pid: int) -> list[int]:
    """The processes ``pid`` started, and theirs, to the last generation."""
    parents = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                parents[int(entry)] = int(Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
    found, todo = [], [pid]
    while todo:
        of = todo.pop()
        children = [c for c, parent in parents.items() if parent == of]
        found += children
        todo += children
    return found


def running(pid: int) -> bool:
    """Whether ``pid`` is a process that has not ended (a zombie has)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def recorded_rows(runs: Path) -> int:
    try:
        run = next(runs.iterdir())
        return max(len((run / "values.csv").read_bytes().splitlines()) - 1, 0)
    except (StopIteration, OSError):
        return 0


def kill_process(pattern: str) -> None:
    found = pids(pattern)
    assert found, f"no process {pattern!r}"
    for pid in found:
        os.kill(pid, signal.SIGKILL)


def run_killing(cfg: Path, runs: Path, kills: list[tuple[str, int]], *args: str) -> tuple[int, str]:
    """``hycosim run`` the project, SIGKILLing each named process ("node NAME" or "server") once the
    records reach its row count; return the run's exit status and stderr."""
    proc = spawn("run", str(cfg), "--runs-dir", str(runs), "--no-progress", *args)
    try:
        for who, at in kills:
            wait_for(lambda: recorded_rows(runs) >= at, 60, f"{at} rows")
            kill_process(f"hycosim {who} {cfg}")
        _, err = proc.communicate(timeout=120)
    finally:
        reap(proc)
    return proc.returncode, err
