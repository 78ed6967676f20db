"""Process handling shared by the benchmarks: free ports, and runs whose children die with them.

A benchmark run that times out must not leave its server and nodes behind to load the
machine under the runs that follow, so every child runs in a process group of its own
and the whole group is killed when the run is given up.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time


def free_port() -> int:
    """A TCP port of 127.0.0.1 that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def kill_group(proc: subprocess.Popen) -> None:
    """SIGKILL ``proc`` and everything it started (it must lead its own group)."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def stop_all(*procs: subprocess.Popen) -> None:
    """Kill the group of every one of ``procs`` still running, and reap it."""
    for p in procs:
        if p.poll() is None:
            kill_group(p)
            p.wait()


def start(cmd: list[str], *, own_session: bool = True, **kwargs) -> subprocess.Popen:
    """Popen in a process group of its own (stop it with :func:`stop_all`), and in a session of
    its own unless not ``own_session``.

    The session matters to the scheduler where the kernel groups processes by session
    (``/proc/sys/kernel/sched_autogroup_enabled``, on by default in most distributions): each
    session is one group, given its fair share of the cores as a whole. The processes of one
    run of a distributed system are started in one session (``own_session=False``), as a
    user's launcher (``hycosim run``, a shell) starts them: in sessions of their own, nine
    processes on two cores were preempted twice as often, and hycosim's ring at 8 nodes cost
    6 % more CPU a step (benchmarks/FINDINGS.md, 2026-12-04)."""
    if own_session:
        return subprocess.Popen(cmd, start_new_session=True, **kwargs)
    return subprocess.Popen(cmd, process_group=0, **kwargs)


def run(cmd: list[str], timeout: float, *, own_session: bool = True, **kwargs) -> subprocess.CompletedProcess:
    """subprocess.run with text output captured, in a process group of its own (and a
    session, as :func:`start`), all of which is killed on timeout; the timeout raises
    RuntimeError naming the command."""
    with start(cmd, own_session=own_session, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
               **kwargs) as proc:
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            kill_group(proc)
            proc.communicate()
            raise RuntimeError(f"timed out after {timeout:g} s (--timeout): {' '.join(cmd[:4])} ...") from None
        return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def wait_all(lead: subprocess.Popen, others: list[subprocess.Popen], timeout: float) -> tuple:
    """``lead.communicate()``, then wait for ``others``, all within one ``timeout``; every group
    still running on the way out (a timeout, or a failure) is killed. Raises
    subprocess.TimeoutExpired past the timeout."""
    deadline = time.monotonic() + timeout
    try:
        out = lead.communicate(timeout=timeout)
        for p in others:
            p.wait(timeout=max(0.0, deadline - time.monotonic()))
        return out
    finally:
        stop_all(lead, *others)


def own_cpu_at_exit(proc: subprocess.Popen, timeout: float) -> float:
    """Wait (up to ``timeout`` s; subprocess.TimeoutExpired past it) until ``proc`` has exited,
    without reaping it, and return the CPU seconds (user and system, all its threads) it used
    itself, its children's not counted. Reap it afterwards (``proc.wait()``).

    Linux keeps an exited process's times in its /proc stat until it is reaped; the rusage a
    reaping wait gives instead adds every child it waited for (the floor's server waits for its
    nodes), and ``Popen.wait`` gives none."""
    deadline = time.monotonic() + timeout
    while os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is None:
        if time.monotonic() > deadline:
            raise subprocess.TimeoutExpired(proc.args, timeout)
        time.sleep(0.005)
    with open(f"/proc/{proc.pid}/stat") as f:
        stat = f.read()
    # After the command's name (in brackets, which may hold spaces): state is field 3, utime 14, stime 15.
    fields = stat[stat.rfind(")") + 2:].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def children() -> dict[int, list[int]]:
    """Every running process's children, by parent pid (from /proc)."""
    kids: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                stat = f.read()
        except OSError:
            continue
        ppid = int(stat[stat.rfind(")") + 2:].split()[1])
        kids.setdefault(ppid, []).append(int(entry))
    return kids


def descendants(pid: int) -> list[int]:
    """The pids of every process below ``pid`` in the process tree, now."""
    kids, found, todo = children(), [], [pid]
    while todo:
        below = kids.get(todo.pop(), [])
        found += below
        todo += below
    return found
