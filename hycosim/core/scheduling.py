"""How the kernel schedules a node's process (``coSimulation.nodeScheduling``).

In a run whose processes outnumber the cores, a release wakes nodes that have no idle core to
go to. Under Linux's default policy a woken node preempts whatever runs on its core, the
server in the middle of the release among them: the server is then off its core before it has
sent the release to the other nodes, and every node after that one waits for it. Scheduled as
batch work (``SCHED_BATCH``), a woken node does not preempt; it runs when the process on the
core sleeps or its slice ends, and the server sends the whole release first. Measured on
2 cores at 8 nodes (benchmarks/FINDINGS.md, ninth entry): 11 % less CPU a macro step and
11 % more steps a second. The server keeps the default policy: it is the run's critical path,
and the answers that wake it should preempt a node.

A node whose run is paced to the wall clock (``realTime``, an asynchronous source) keeps the
default policy too: there a wake-up's latency is what matters, and a batch process woken on a
busy core may wait out a time slice (milliseconds) for it.
"""

from __future__ import annotations

import os


def batch_nodes(policy: str, processes: int, cpus: int | None, paced: bool) -> bool:
    """Resolve a ``nodeScheduling`` (``auto``, ``batch``, ``normal``) for a run of ``processes``
    co-simulation processes (the server and its nodes) on ``cpus`` cores; ``paced``: a run held
    to the wall clock. ``auto`` is ``batch`` where the processes outnumber the cores and the
    run is not paced."""
    if policy == "auto":
        return not paced and processes > (cpus or 1)
    return policy == "batch"


def schedule_as_batch() -> bool:
    """The calling thread, and every thread and process it starts from now on (a model's tool
    started as a process of its own too), scheduled as batch work (``SCHED_BATCH``); call it
    before a process starts its threads (Zenoh's, a model's).
    False where the system has no such policy or refuses it (not Linux, a sandbox): the process
    then runs as before."""
    try:
        os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
    except (AttributeError, OSError):
        return False
    return True
