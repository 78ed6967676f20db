"""``hycosim run FILE --in-process``: the server's master and every node in one process, no sockets.

The same project file, the same master (:class:`hycosim.master.relay.Relay`) and the same
node runtime as a distributed run, with the transport replaced by calls
(:mod:`hycosim.transport.local_bus`): each release steps every node there and then, in this
thread. The run directory is a distributed run's, ``values.csv`` byte for byte.

What one process cannot give: a node whose native code crashes takes the run down with it,
and no node is started again (``--restarts``); nobody outside can attach (no status
queryable, no dashboard, no gateway for bridge FMUs); asynchronous sources are refused (see
:func:`hycosim.core.config.in_process_refusals`).
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable

from hycosim.core import logs
from hycosim.core.config import LoadedProject, in_process_refusals
from hycosim.core.schema import ScenarioAction
from hycosim.core.folders import run_dir_for
from hycosim.transport.local_bus import LocalBus

from hycosim.node.loader import NodeLoadError, load_node
from hycosim.node.interface import NodeModelError
from hycosim.node.in_process import HostedNode
from hycosim.node.runtime import NodeRunError
from hycosim.master.main import IN_PROCESS, serve
from hycosim.master.relay import PointGate, Relay


class CannotHost(ValueError):
    """A project with nodes an in-process run cannot host; the message names each and why."""


def check_hostable(loaded: LoadedProject) -> None:
    """Raise :class:`CannotHost` naming every node one process cannot host, and why."""
    refused = in_process_refusals(loaded.project)
    if refused:
        raise CannotHost("--in-process cannot host " + "; ".join(f"node {n!r}: {why}" for n, why in refused.items())
                         + " (run it without --in-process)")


def run_in_process(loaded: LoadedProject, *, runs_dir: Path = Path("runs"),
                   on_progress: Callable[[dict[str, Any]], None] | None = None,
                   gate: PointGate | None = None, on_relay: Callable[[Relay], None] | None = None,
                   scenario: list[ScenarioAction] | None = None,
                   record: str | None = None) -> tuple[int, Path | None, str]:
    """Run the project in this process; return (exit code, run directory, message) as
    :func:`hycosim.master.main.serve` does. Raise :class:`CannotHost` before anything is
    written for a node one process cannot host. ``gate`` and ``on_relay``: a caller that drives
    the run point by point (:func:`hycosim.open`), as :func:`~hycosim.master.main.serve` takes them."""
    check_hostable(loaded)
    base = loaded.path.parent if loaded.path else Path.cwd()
    models = {}
    for spec in loaded.project.nodeLists:  # before a run directory is made: a model that cannot load is named
        try:
            models[spec.nodeName] = load_node(spec, base, loaded.project.coSimulation)
        except (NodeLoadError, NodeModelError) as exc:
            return 3, None, str(exc)
    run_dir = run_dir_for(runs_dir, loaded.name)
    logs.configure(run_dir / "server.log.jsonl")  # the nodes' log lines go there too
    bus = LocalBus(loaded.project.projectName)
    hosted: list[HostedNode] = []
    try:
        for name, model in models.items():
            runtime = HostedNode(loaded, name, model, IN_PROCESS)
            try:
                runtime.host(bus)
            except (NodeRunError, NodeModelError) as exc:
                return 3, run_dir, str(exc)
            hosted.append(runtime)
        progress = None if on_progress is None else (lambda p: on_progress(asdict(p)))
        return serve(loaded, run_dir=run_dir, bus=bus, on_progress=progress, gate=gate, on_relay=on_relay,
                     scenario=scenario, record=record)
    finally:
        for runtime in hosted:
            try:
                runtime.close()
            except Exception:  # a model's teardown on the way out: the run's outcome stands
                pass
