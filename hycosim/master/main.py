"""``hycosim server FILE``: open the router session, run the relay, report the outcome."""

from __future__ import annotations

import json
import os
import platform
import sys
from dataclasses import asdict
from importlib import metadata
from pathlib import Path
from typing import Any, Callable

import structlog

from hycosim import __version__
from hycosim.core import json_text, logs, signals
from hycosim.core.config import LoadedProject, gateway_address, server_endpoint
from hycosim.core.endpoints import GATEWAY_PORT, EndpointError, parse_address, parse_endpoint
from hycosim.core.folders import make_folder, run_dir_for
from hycosim.core.heap import set_up_frozen
from hycosim.transport.local_bus import LocalBus
from hycosim.transport.security import SecurityError, router_security
from hycosim.transport.session import ConnectError, open_session, router_config, server_socket

from hycosim.master import checkpoints
from hycosim.master.coordinator import GuardEvaluationError
from hycosim.master.recorder import Recorder, RecordError
from hycosim.core.extras import install_hint, missing_modules
from hycosim.master.parquet_tables import recorded_rows
from hycosim.master.algorithms.choice import AlgorithmLoadError, project_algorithm
from hycosim.master.observers import ObserverLoadError, project_observers
from hycosim.master.scenario import from_meta
from hycosim.master.relay import PointGate, Relay, RunError
from hycosim.core.schema import ScenarioAction
from hycosim.transport.server_side import InProcessTransport, Transport, ZenohTransport


# The project file as the run began, in its run directory.
PROJECT_COPY = "project.json"
# What meta.json's endpoint says of an in-process run.
IN_PROCESS = "inprocess"


def _versions() -> dict[str, str]:
    found = {"python": platform.python_version(), "hycosim": __version__}
    for dist in ("eclipse-zenoh", "fmpy", "msgpack", "pydantic", "mujoco", "torch"):
        try:
            found[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            pass
    return found


def _project_differences(recorded: Any, given: Any, at: str = "") -> list[str]:
    """Where two project files differ, as ``path: recorded → given`` (the first few)."""
    if type(recorded) is dict and type(given) is dict:
        found = []
        for key in sorted(set(recorded) | set(given), key=str):
            path = f"{at}.{key}" if at else str(key)
            if key not in given:
                found.append(f"{path} is gone")
            elif key not in recorded:
                found.append(f"{path} is new")
            else:
                found += _project_differences(recorded[key], given[key], path)
        return found
    if type(recorded) is list and type(given) is list and len(recorded) == len(given):
        return [d for i, (a, b) in enumerate(zip(recorded, given)) for d in _project_differences(a, b, f"{at}[{i}]")]
    if recorded != given:
        return [f"{at or 'the file'}: {json.dumps(recorded)[:60]} → {json.dumps(given)[:60]}"]
    return []


def _resume_plan(loaded: LoadedProject, run_dir: Path) -> tuple[dict[str, Any], dict[str, int], int]:
    """The meta, record offsets and recorded steps of a run to resume; ValueError saying why it cannot be."""
    try:
        meta = json_text.loads((run_dir / "meta.json").read_bytes())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{run_dir}: not a run directory (no readable meta.json: {exc})") from None
    if type(meta) is not dict:
        raise ValueError(f"{run_dir}: not a run directory (its meta.json holds no object)")
    if meta.get("config_sha256") != loaded.digest:
        differ = ["(the recorded copy is missing)"]
        try:
            differ = _project_differences(json_text.loads((run_dir / PROJECT_COPY).read_bytes()),
                                          json_text.loads(loaded.path.read_bytes()) if loaded.path else {}) or \
                ["(only in layout)"]
        except (OSError, ValueError, RecursionError):  # a hint only; the comparison recurses per level too
            pass
        raise ValueError(f"{run_dir} was run with another project file than {loaded.path}: "
                         f"{'; '.join(differ[:5])}{' …' if len(differ) > 5 else ''}")
    cp, passed = checkpoints.latest(run_dir, loaded.digest, project=loaded.project)
    if cp is None:
        raise ValueError(f"{run_dir}: no checkpoint to resume from"
                         + (f" ({'; '.join(passed)})" if passed else " (was coSimulation.checkpointEvery set?)"))
    try:
        recorded = recorded_rows(run_dir)
    except (OSError, ValueError):
        recorded = cp.step
    earlier = meta.get("checkpoints_passed_over")  # the relay adds what it passes over on restoring
    if earlier is not None and type(earlier) is not list:
        del meta["checkpoints_passed_over"]
    return meta, cp.server["records"], recorded


def _router_session(loaded: LoadedProject, endpoint: str, security: dict | None, log: Any) -> Any:
    """The server's Zenoh router on ``endpoint``, and on a Unix socket beside it for the nodes
    on this host where the project allows one (transport.session.local_socket) and it can be
    listened on; ConnectError where the router cannot be opened."""
    cosim = loaded.project.coSimulation
    local, why_not = server_socket(endpoint) if cosim.localSocket else (None, None)
    if why_not is not None:
        log.warning(f"no Unix socket for nodes on this host: {why_not}")
    try:
        return open_session(router_config(endpoint, security=security, local=local, low_latency=cosim.lowLatency),
                            endpoint)
    except ConnectError as exc:
        if local is None or str(local) not in str(exc):
            raise
        # The socket is a shortcut: where it cannot be listened on, the nodes take TCP.
        log.warning("no Unix socket for nodes on this host", socket=str(local), error=str(exc))
        return open_session(router_config(endpoint, security=security, low_latency=cosim.lowLatency), endpoint)


def serve(loaded: LoadedProject, *, listen: str | None = None, runs_dir: Path = Path("runs"),
          run_dir: Path | None = None, progress_jsonl: bool = False,
          gateway: str | None = None, resume: Path | None = None,
          bus: LocalBus | None = None, on_progress: Callable[[Any], None] | None = None,
          gate: PointGate | None = None, on_relay: Callable[[Relay], None] | None = None,
          scenario: list[ScenarioAction] | None = None, record: str | None = None) -> tuple[int, Path | None, str]:
    """Run one co-simulation as its server; return (exit code, run directory, message).

    Addresses and the credentials and certificate files are checked before anything is
    written: one that cannot be used gives exit code 2 and no run directory. ``resume``: go
    on with the run in that directory, whose server died, from its last complete checkpoint
    (exit code 2 if it cannot be). ``bus``: the nodes are hosted in this process and attached
    to it (an in-process run): no session, no gateway, no status queryable. ``on_progress``:
    called with the relay's Progress about ten times a second. ``gate``: when the step from
    each point is taken (:class:`hycosim.master.relay.PointGate`; default at once); ``on_relay``
    is given the relay before it runs (a Python caller reads its points through it).
    ``scenario``: overrides in time beside the project's own (``--scenario FILE``, checked);
    kept in ``meta.json``, where a resumed run finds them. ``record``: the tables' format
    (``csv`` or ``parquet``; default the project's ``recording.format``; a resumed run keeps its own).
    """
    def done(code: int, run_dir: Path | None, message: str) -> tuple[int, Path | None, str]:
        # A launcher reading --progress-jsonl learns the outcome from this line, on every path.
        if progress_jsonl:
            print(json.dumps({"done": code, "message": message, "run_dir": str(run_dir) if run_dir else None}),
                  flush=True)
        return code, run_dir, message

    if bus is not None:
        endpoint, gw, gateway_required, security = IN_PROCESS, None, False, None
    else:
        try:
            endpoint = str(parse_endpoint(listen)) if listen else server_endpoint(loaded.project.serverIP)
        except EndpointError as exc:
            return done(2, None, f"{'--listen' if listen else 'serverIP'}: {exc}")
        try:
            gw = parse_address(gateway, GATEWAY_PORT) if gateway else gateway_address(loaded.project, endpoint)
        except EndpointError as exc:
            return done(2, None, f"{'--gateway' if gateway else 'gatewayIP'}: {exc}")
        gateway_required = bool(gateway or loaded.project.gatewayIP)
        try:
            # Read before the run directory is made: a missing or unreadable credentials or
            # certificate file is bad input (exit 2), like an address, not a failed run.
            security = router_security(loaded, endpoint)
        except SecurityError as exc:
            return done(2, None, str(exc))
    record = record or loaded.project.recording.format
    if record == "parquet" and missing_modules("parquet"):
        return done(2, None, f"recording as Parquet needs pyarrow: {install_hint('parquet')}")
    try:  # the user's code: what cannot be made is bad input, named before a run directory is made
        observers = project_observers(loaded)
        algorithm = project_algorithm(loaded)
    except (ObserverLoadError, AlgorithmLoadError) as exc:
        return done(2, None, f"{loaded.path or 'the project'}: {exc}")
    resume_at, recorded = None, None
    if resume is not None:
        try:
            old_meta, resume_at, recorded = _resume_plan(loaded, resume)
        except ValueError as exc:
            return done(2, None, f"--resume: {exc}")
        run_dir = resume
    try:
        if run_dir is None:
            run_dir = run_dir_for(runs_dir, loaded.name)
        else:
            make_folder(run_dir)
    except OSError as exc:
        return done(2, None, f"{exc.filename or run_dir or runs_dir}: {exc.strerror or exc}")
    logs.configure(run_dir / "server.log.jsonl")
    log = structlog.get_logger("server")
    meta: dict[str, Any] = {
        "project": loaded.name, "config": str(loaded.path) if loaded.path else None,
        "config_sha256": loaded.digest, "endpoint": endpoint, "versions": _versions(),
        "stepSize": loaded.project.coSimulation.stepSize, "stopTime": loaded.project.coSimulation.stopTime,
        "realTime": loaded.project.coSimulation.realTime,
        "lowLatency": loaded.project.coSimulation.lowLatency,
        "waitStrategy": loaded.project.coSimulation.waitStrategy, "zenoh_runtime": os.environ.get("ZENOH_RUNTIME"),
    }
    if scenario:
        meta["scenario"] = [a.model_dump(by_alias=True, exclude_none=True) for a in scenario]
    meta["recording"] = record
    if resume_at is not None:
        meta = {**old_meta, "endpoint": endpoint, "versions": meta["versions"]}
        record = meta.get("recording", "csv") if meta.get("recording") in ("csv", "parquet") else "csv"
        if not scenario and old_meta.get("scenario"):
            try:
                scenario = from_meta(old_meta["scenario"], loaded.project, loaded.routes)
            except ValueError as exc:
                return done(2, None, f"--resume: {resume / 'meta.json'}: {exc}")
    try:
        # In one process the master's thread steps every node: a process of its own writes the rows.
        recorder = Recorder(run_dir, loaded, meta, resume_at=resume_at, rows_apart=bus is not None,
                            record_format=record)
        if resume_at is None and loaded.path is not None:
            # What the project was, for a resume to compare with (the hash alone cannot say where it differs).
            (run_dir / PROJECT_COPY).write_bytes(loaded.path.read_bytes())
    except OSError as exc:
        return done(3, run_dir, f"cannot write {run_dir / PROJECT_COPY}: {exc.strerror or exc}")
    except RecordError as exc:
        return done(3, run_dir, str(exc))
    if progress_jsonl:
        def on_progress(p: Any) -> None:
            print(json.dumps({"progress": asdict(p), "run_dir": str(run_dir)}), flush=True)
    session = None
    if bus is not None:
        transport: Transport = InProcessTransport(bus)
    else:
        try:
            session = _router_session(loaded, endpoint, security, log)
        except KeyboardInterrupt as exc:
            recorder.close("interrupted", reason=f"{signals.describe(exc)} before the run started")
            return done(signals.exit_code(exc), run_dir, f"{signals.describe(exc)} before the run started")
        except Exception as exc:  # ConnectError (or what Zenoh made of the security settings), with its message
            recorder.close("failed", reason=str(exc))
            return done(3, run_dir, str(exc))
        transport = ZenohTransport(session)
    relay = Relay(loaded, transport, recorder, progress_every_s=0.1, on_progress=on_progress,
                  gateway_address=(gw.host, gw.port) if gw is not None else None,
                  gateway_required=gateway_required, resume=recorded, gate=gate, scenario=scenario,
                  algorithm=algorithm)
    for observer in observers:
        relay.add_observer(observer)
    if on_relay is not None:
        on_relay(relay)
    try:
        with set_up_frozen():
            relay.run()
        code, message = 0, f"{'stopped after' if relay.stopped else 'completed'} {recorder.meta['steps']} macro steps"
        if relay.barrier.ending.by is not None:
            e = relay.barrier.ending.by
            message += f"; node {e['node']!r} ended the simulation at t={e['t']:g} s: {e['message']}"
    except (RunError, RecordError, GuardEvaluationError) as exc:
        log.error("run failed", error=str(exc))
        code, message = 3, str(exc)
    except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM or SIGHUP
        code, message = signals.exit_code(exc), f"{signals.describe(exc)}; results so far are flushed"
        if not recorder.closed:  # interrupted while the relay declared itself, before its own shutdown
            recorder.close("interrupted", reason=signals.describe(exc))
    except Exception as exc:  # a bug, not bad input: keep the traceback in the log
        log.exception("internal error")
        code, message = 4, f"internal error {type(exc).__name__}: {exc} (traceback in {run_dir / 'server.log.jsonl'})"
    finally:
        if session is not None:
            session.close()
    return done(code, run_dir, message)


if __name__ == "__main__":  # pragma: no cover - the CLI is the entry point
    sys.exit("use: hycosim server FILE")
