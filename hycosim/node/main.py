"""``hycosim node NAME FILE``: load one node's implementation and attach it to the server."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import structlog

from hycosim.core import logs, signals
from hycosim.core.config import LoadedProject, server_endpoint
from hycosim.core.endpoints import EndpointError, parse_endpoint
from hycosim.core.heap import set_up_frozen
from hycosim.core.scheduling import schedule_as_batch
from hycosim.transport.security import SecurityError, node_password
from hycosim.transport.session import ConnectError
from hycosim.core.signals import FAILED_ELSEWHERE, NODE_UNLOADABLE

from hycosim.node.loader import NodeLoadError, load_node
from hycosim.node.interface import NodeModelError
from hycosim.node.over_zenoh import ZenohNode
from hycosim.node.runtime import NodeRunError, RunFailedElsewhere


def run_node(loaded: LoadedProject, name: str, connect: str | None = None,
             log_file: Path | None = None, password_file: Path | None = None) -> tuple[int, str]:
    """Run one node to the end of the co-simulation; return (exit code, message)."""
    logs.configure(log_file)
    try:
        spec = loaded.project.node(name)
    except KeyError:
        names = ", ".join(n.nodeName for n in loaded.project.nodeLists)
        return 2, f"{loaded.path}: no node named {name!r} (nodes: {names})"
    try:
        endpoint = str(parse_endpoint(connect)) if connect else server_endpoint(loaded.project.serverIP)
    except EndpointError as exc:
        return 2, f"{'--connect' if connect else 'serverIP'}: {exc}"
    # Before any thread starts (Zenoh's, a model's): each takes its policy from this one.
    if loaded.project.batch_nodes(os.cpu_count()) and schedule_as_batch():
        structlog.get_logger("node").bind(node=name).info("scheduled", policy="batch")
    interrupted: list[int] = []  # the stop signal that came, if any
    previous = signals.raise_on_stop(interrupted)
    try:
        password = node_password(loaded, name, password_file)
        impl = load_node(spec, loaded.path.parent if loaded.path else Path.cwd(), loaded.project.coSimulation)
        runtime = ZenohNode(loaded, name, impl, endpoint, password=password)
        with set_up_frozen():
            runtime.run()
    except RunFailedElsewhere as exc:
        return FAILED_ELSEWHERE, str(exc)
    except NodeLoadError as exc:
        # Cannot pass by itself (a model that does not load, a missing file): 2, never restarted.
        if interrupted:
            stop = signals.Stopped(interrupted[0])
            return signals.exit_code(stop), f"node {name!r} {signals.describe(stop)}"
        return NODE_UNLOADABLE, str(exc)
    except (NodeRunError, NodeModelError, ConnectError, SecurityError) as exc:
        if interrupted:
            # Ctrl-C while a model's extension module initialised surfaces as an ImportError.
            stop = signals.Stopped(interrupted[0])
            return signals.exit_code(stop), f"node {name!r} {signals.describe(stop)}"
        return 3, str(exc)
    except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM or SIGHUP
        return signals.exit_code(exc), f"node {name!r} {signals.describe(exc)}"
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    if spec.asynchronous and not spec.replay:
        return 0, f"node {name!r} finished after {runtime.samples} samples"
    return 0, f"node {name!r} finished after {runtime.steps} steps"
