"""The ``hycosim`` command line. User-facing output goes through here, not through logs.

Exit codes: 0 success, 2 bad input (config, arguments, run directory), 3 a run that
failed (timeout, lost node, server gone), 4 an internal error or an invalid FMU built,
5 a node whose run the server stopped because it failed elsewhere (the server says why),
130 Ctrl-C.
"""

from __future__ import annotations

import json
import math
import os
import signal
import sys
import time
from dataclasses import asdict
from functools import partial
from pathlib import Path
from typing import Annotated, Any, NoReturn, Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from hycosim.core import signals
from hycosim.core.config import ConfigError, LoadedProject, load_project
from hycosim.core.endpoints import GATEWAY_PORT, Address, EndpointError, parse_address, parse_endpoint
from hycosim.core.signals import ignore_stops

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="hycosim: hybrid time/event co-simulation on FMI, relayed over Zenoh.")
out = Console(soft_wrap=True)
err = Console(stderr=True, soft_wrap=True)


def _finite(value: float | None) -> float | None:
    """A float option's check where its range does not make one: Typer refuses nan for an option
    with a bound, but takes nan and inf without one and inf past a lower bound alone."""
    if value is not None and not math.isfinite(value):
        raise typer.BadParameter(f"{value} is not a finite number")
    return value


def _load(path: Path) -> LoadedProject:
    try:
        return load_project(path)
    except ConfigError as exc:
        err.print(f"[red]error:[/red] {exc.source}: {len(exc.issues)} error(s)", highlight=False)
        for issue in exc.issues:
            err.print(f"  {exc.source}: {issue.render()}", highlight=False, markup=False)
        raise typer.Exit(2) from None


# Beside a package, the parts of a project SSP has no word for (serverIP, events, asynchronous
# nodes, coSimulation keys): `run` and `validate` of system.ssp read system.hycosim.json.
SSP_SIDE_SUFFIX = ".hycosim.json"


def _from_ssp(package: Path, project_file: Path, side: Path | None = None, step: float | None = None,
              stop: float | None = None) -> Path:
    """Import the SSP package into ``project_file`` (its FMUs in a folder beside it); exit 2 with
    what is wrong."""
    from hycosim.core import json_text
    from hycosim.fmu_bridge.ssp import SspError, project_from_ssp

    side = side or (package.with_name(package.stem + SSP_SIDE_SUFFIX) if
                    package.with_name(package.stem + SSP_SIDE_SUFFIX).is_file() else None)
    try:
        extra = json_text.loads(side.read_bytes()) if side is not None else None
        if extra is not None and type(extra) is not dict:
            raise ValueError("it holds no JSON object")
    except (OSError, ValueError) as exc:
        err.print(f"[red]error:[/red] {side}: cannot read the side file ({exc})", highlight=False)
        raise typer.Exit(2) from None
    try:
        doc = project_from_ssp(package, project_file.parent / f"{project_file.stem}-fmus", side=extra, step=step,
                               stop=stop)
    except SspError as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}", highlight=False)
        raise typer.Exit(2) from None
    try:
        project_file.write_text(json.dumps(doc, indent=1))
    except OSError as exc:
        err.print(f"[red]error:[/red] {escape(str(project_file))}: cannot write ({exc.strerror or exc})", highlight=False)
        raise typer.Exit(2) from None
    return project_file


def _project_file(file: Path) -> Path:
    """The project file to use for FILE: itself, or for an SSP package the project imported from
    it (into a hidden folder beside it, remade each time)."""
    if file.suffix.lower() != ".ssp":
        return file
    folder = file.parent / f".{file.name}.d"
    try:
        folder.mkdir(exist_ok=True)
    except OSError as exc:
        err.print(f"[red]error:[/red] {escape(str(folder))}: cannot make the folder the package is imported into "
                  f"({exc.strerror or exc}); import it elsewhere with: hycosim import {escape(str(file))} -o DIR/project.json",
                  highlight=False)
        raise typer.Exit(2) from None
    return _from_ssp(file, folder / "project.json")


def _print_table(table: Table) -> None:
    """A table on stdout, whole: on a pipe or in a file rich would cut cells to 80 columns
    (``Float64_fixed_pa…``), and a name cut short is a wrong name."""
    (out if out.is_terminal else Console(width=100_000)).print(table)


def _end_process(code: int) -> NoReturn:
    """End a node or server process with its outcome, now that it is said and recorded.

    Without the interpreter's finalisation and the C exit handlers: there the native libraries
    the process loaded (an FMU's binary, MuJoCo, Zenoh's runtime) tear themselves down, after
    the run is over, and one such teardown aborted a rod node that had finished cleanly (glibc:
    "corrupted double-linked list", past the point where Python's fault handler is off), which
    its launcher rightly took for a crash. Nothing is left for them to do: the session, the
    FMU and the record files are closed, and log files are line-buffered.
    """
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


def _say_outcome(console: Console, text: str) -> None:
    """Print a process's last word. Its stderr may be a file on a disk that just filled up
    (a launched node's): the exit status still tells the outcome, so a failed print is let go."""
    try:
        console.print(text, highlight=False)
    except OSError:
        pass


def _endpoint(option: str, value: str, parse=parse_endpoint) -> str:
    """An address given on the command line, normalised; exit 2 naming the option if unusable."""
    try:
        return str(parse(value))
    except EndpointError as exc:
        err.print(f"[red]error:[/red] {option}: {exc}", highlight=False)
        raise typer.Exit(2) from None


@app.command()
def validate(
    file: Path,
    models: Annotated[bool, typer.Option(help="also check that each node's model or FMU exists and takes "
                                              "the node's ports and parameters (imports the models)")] = True,
) -> None:
    """Check a project JSON (or an SSP package): print OK, or every error with its JSON path and a hint."""
    loaded = _load(_project_file(file))
    p = loaded.project
    if models:
        from hycosim.clients.loader import NodeLoadError, check_node

        problems = []
        for i, node in enumerate(p.nodeLists):
            try:
                check_node(node, loaded.path.parent, p.coSimulation)
            except NodeLoadError as exc:
                problems.append(f"{file}: nodeLists[{i}]: {exc}")
        if problems:
            err.print(f"[red]error:[/red] {file}: {len(problems)} node(s) cannot be loaded", highlight=False)
            for line in problems:
                err.print(f"  {line}", highlight=False, markup=False)
            raise typer.Exit(2)
        _check_retakes(file, loaded)
    out.print(f"OK {file}: project {p.projectName!r}, {len(p.nodeLists)} nodes, {len(p.linkLists)} links, "
              f"{len(loaded.routes)} routes, {len(p.events)} events" + ("" if models else " (models not checked)"),
              highlight=False)
    if models:
        _warn_algebraic_loops(file, loaded)
    if p.coSimulation.checkpointEvery is not None and models:
        from hycosim.clients.loader import why_no_checkpoint

        unable = [(n.nodeName, why) for n in p.nodeLists if (why := why_no_checkpoint(n, loaded.path.parent))]
        for name, why in unable:
            err.print(f"[yellow]warning:[/yellow] coSimulation.checkpointEvery: node {name!r} cannot take part in "
                      f"checkpoints: {why}; the run takes none, and a lost node ends it", highlight=False)
    bridged = [n.nodeName for n in p.nodeLists if not (n.model or n.fmu or n.replay or n.asynchronous)]
    if bridged:
        out.print(f"{len(bridged)} node(s) wait for a bridge FMU in some tool: {', '.join(bridged)} "
                  f"(build them with: hycosim fmu build {file} -o fmus)", highlight=False)


def _check_retakes(file: Path, loaded: Any) -> None:
    """Iterative coupling and the error-controlled step need every stepping node to take a step
    again: name each one that cannot, exit 2."""
    from hycosim.clients.loader import why_no_retake

    cosim = loaded.project.coSimulation
    for key, variable in (("iterate", False), ("stepControl", True)):
        if getattr(cosim, key) is None:
            continue
        unable = [(n.nodeName, why) for n in loaded.project.stepping_nodes()
                  if (why := why_no_retake(n, loaded.path.parent, variable))]
        if unable:
            err.print(f"[red]error:[/red] {file}: coSimulation.{key}: every stepping node must be able to take a step "
                      f"again{' with another length' if variable else ''}", highlight=False)
            for name, why in unable:
                err.print(f"  node {name!r}: {why}", highlight=False, markup=False)
            raise typer.Exit(2)
    if cosim.iterate is not None and cosim.iterate.interpolate:
        from hycosim.clients.loader import why_no_interpolation

        for n in loaded.project.stepping_nodes():
            if n.input and (why := why_no_interpolation(n, loaded.path.parent)):
                err.print(f"[yellow]warning:[/yellow] {file}: coSimulation.iterate.interpolate: node "
                          f"{n.nodeName!r} holds its inputs at the step's end value: {why}", highlight=False)


def _warn_algebraic_loops(file: Path, loaded: Any) -> None:
    """Name each cycle of direct feedthrough, which a step-by-step scheme takes a step late."""
    from hycosim.clients.loader import feedthrough_of
    from hycosim.core.coupling import algebraic_loops

    p = loaded.project
    feedthrough = {n.nodeName: feedthrough_of(n, loaded.path.parent) for n in p.stepping_nodes()}
    for loop in algebraic_loops(loaded.routes, feedthrough):
        if p.coSimulation.iterate is None:
            err.print(f"[yellow]warning:[/yellow] {file}: algebraic loop {' → '.join(loop)}: "
                      f"{p.coSimulation.coupling.replace('gauss-seidel', 'Gauss-Seidel').replace('jacobi', 'Jacobi')} "
                      "coupling takes it a macro step late; coSimulation.iterate solves it at each step",
                      highlight=False)
        else:
            out.print(f"algebraic loop {' → '.join(loop)}: solved at each step by coSimulation.iterate",
                      highlight=False)


@app.command()
def server(
    file: Path,
    listen: Annotated[Optional[str], typer.Option(help="Zenoh endpoint to listen on (default: serverIP)")] = None,
    runs_dir: Annotated[Path, typer.Option(help="where run directories are made")] = Path("runs"),
    run_dir: Annotated[Optional[Path], typer.Option(help="exact run directory to write")] = None,
    progress_jsonl: Annotated[bool, typer.Option(help="print progress as JSON lines (for launchers)")] = False,
    gateway: Annotated[Optional[str], typer.Option(help="HOST:PORT for bridge FMUs (default: gatewayIP, "
                                                        "or the server's port + 1)")] = None,
    resume: Annotated[Optional[Path], typer.Option(help="go on with the run in this directory (its server died) "
                                                       "from its last checkpoint")] = None,
) -> None:
    """Run the relay server for one co-simulation (Zenoh nodes and bridge FMUs)."""
    from hycosim.server.main import serve

    loaded = _load(file)
    code, rdir, message = serve(loaded, listen=listen, runs_dir=runs_dir, run_dir=run_dir,
                                progress_jsonl=progress_jsonl, gateway=gateway, resume=resume)
    if code:
        _say_outcome(err, f"[red]error:[/red] {message}" + (f"\n  results so far: {rdir}" if rdir else ""))
    elif not progress_jsonl:
        _say_outcome(out, f"{message}; results in {rdir}")
    _end_process(code)


@app.command()
def node(
    name: str,
    file: Path,
    connect: Annotated[Optional[str], typer.Option(help="server endpoint, e.g. tcp/HOST:7447")] = None,
    log_file: Annotated[Optional[Path], typer.Option(help="append JSON-lines logs here (default: stderr)")] = None,
    password_file: Annotated[Optional[Path], typer.Option(help="this node's password (user = node name), "
                                                               "when the project has 'security'")] = None,
) -> None:
    """Attach one node of the project to a running server (local or on another host)."""
    from hycosim.clients.main import run_node

    loaded = _load(file)
    code, message = run_node(loaded, name, connect, log_file, password_file)
    _say_outcome(err if code else out, ("[red]error:[/red] " if code else "") + message)
    _end_process(code)


@app.command()
def run(
    file: Path,
    listen: Annotated[Optional[str], typer.Option(help="endpoint for the server (default: a free loopback port)")] = None,
    runs_dir: Annotated[Path, typer.Option(help="where run directories are made")] = Path("runs"),
    progress: Annotated[bool, typer.Option(help="show the progress bar")] = True,
    restarts: Annotated[int, typer.Option(min=0, help="with checkpoints: how often a node process that dies "
                                                       "is started again")] = 3,
    resume: Annotated[Optional[Path], typer.Option(help="go on with the run in this directory (its server died) "
                                                       "from its last checkpoint")] = None,
    dashboard: Annotated[bool, typer.Option(help="watch the run in a browser (hycosim dashboard)")] = False,
    dashboard_port: Annotated[int, typer.Option(min=0, max=65535, help="the dashboard's port on 127.0.0.1")] = 8050,
) -> None:
    """Run the server and every node as local processes on loopback (FILE: a project JSON or an SSP package)."""
    from hycosim.core.security import SecurityError, router_security
    from hycosim.embedded import run_embedded
    from hycosim.server.report import summarise

    file = _project_file(file)
    loaded = _load(file)
    listen = _endpoint("--listen", listen) if listen else None
    if resume is not None and not (resume / "meta.json").is_file():
        err.print(f"[red]error:[/red] --resume: {resume} is not a run directory (no meta.json)", highlight=False)
        raise typer.Exit(2)
    if dashboard and loaded.project.security is not None and loaded.project.security.credentials:
        err.print("[red]error:[/red] --dashboard: this project's server requires credentials; attach a dashboard "
                  "with its own: hycosim dashboard ENDPOINT --user NAME --password-file FILE", highlight=False)
        raise typer.Exit(2)
    try:
        # The server reads these again; read here, a missing file is named before a run directory is made.
        router_security(loaded, listen or "")
    except SecurityError as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}", highlight=False)
        raise typer.Exit(2)
    result = run_embedded(loaded, file, listen=listen, runs_dir=runs_dir, console=err, show_progress=progress,
                          restarts=restarts, resume=resume, dashboard_port=dashboard_port if dashboard else None)
    if result.code >= 128:
        ignore_stops()  # a Ctrl-C pressed twice: the run is over, say so
    if result.code:
        err.print(f"[red]error:[/red] {result.message}\n  results so far: {result.run_dir}", highlight=False)
        raise typer.Exit(result.code)
    summary = summarise(result.run_dir)
    _print_summary(summary)


def _print_summary(s) -> None:
    rate = f"{s.steps_per_s:,.0f} steps/s" if s.steps_per_s else "-"
    wall = f"{s.wall_time_s:.2f} s" if s.wall_time_s else "-"
    out.print(f"[bold]{s.status}[/bold]: {s.steps} macro steps in {wall} ({rate}); "
              f"{len(s.mode_switches)} mode switches; results in {s.run_dir}", highlight=False)
    if s.ended_by:
        e = s.ended_by
        out.print(f"node {e['node']!r} ended the simulation at t={e['t']:g} s (after step {e['step']}): "
                  f"{e['message']}", highlight=False, markup=False)
    if s.non_finite:
        firsts = ", ".join(f"{port} at " + (f"step {at['step']} " if "step" in at else "") + f"(t={at['t']:g} s)"
                           for port, at in sorted(s.non_finite.items(), key=lambda item: item[1]["t"]))
        out.print(f"[yellow]warning:[/yellow] NaN or infinite values, first on each port: {firsts}", highlight=False)


@app.command()
def report(
    run_dir: Path,
    as_json: Annotated[bool, typer.Option("--json", help="print the summary as JSON")] = False,
) -> None:
    """Summarise a run: rate, who held the barrier, slowest steps, lateness, mode switches."""
    from hycosim.server.report import RunDirError, summarise

    try:
        s = summarise(run_dir)
    except RunDirError as exc:
        err.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(2) from None
    if as_json:
        out.print_json(json.dumps(asdict(s)))
        return
    _print_summary(s)
    if s.reason:
        out.print(f"reason: {s.reason}", highlight=False)
    if s.coupling:
        out.print(f"coupling: {s.coupling}", highlight=False)
    for label, text in (("iteration", s.iteration), ("step control", s.step_control)):
        if text:
            out.print(f"{label}: {text}", highlight=False)
    if s.takes:
        out.print(f"takes per step: mean {s.takes['mean']:.2f}, max {s.takes['max']:g}; "
                  f"{s.takes['steps_taken_again']:g} steps taken more than once", highlight=False)
    if s.not_converged:
        worst = s.not_converged.get("worst") or {}
        out.print(f"[yellow]{s.not_converged['not_converged']} steps did not converge[/yellow]"
                  + (f"; worst: input {worst.get('port')} at t={worst.get('t')} s changed by {worst.get('change')}"
                     if worst else ""), highlight=False)
    if s.step_sizes:
        out.print(f"macro steps used: {s.step_sizes['min']:.3g} to {s.step_sizes['max']:.3g} s, "
                  f"mean {s.step_sizes['mean']:.3g} s", highlight=False)
    table = Table(title="who held the barrier")
    for col in ("node", "steps taken", "share of waiting", "steps held", "mean arrival (ms)"):
        table.add_column(col)
    for node in sorted(set(s.holder_share) | set(s.mean_arrival_ms)):
        share = s.holder_share.get(node)
        table.add_row(node, str(s.node_steps.get(node, "-")), "-" if share is None else f"{100 * share:.1f} %",
                      str(s.holder_steps.get(node, 0)),
                      f"{s.mean_arrival_ms.get(node, float('nan')):.3f}")
    out.print(table)
    slow = Table(title="slowest steps")
    for col in ("step", "t (s)", "wait (ms)", "held by"):
        slow.add_column(col)
    for row in s.slowest_steps:
        slow.add_row(str(row["step"]), f"{row['t']:.4f}", f"{row['wait_ms']:.3f}", row["holder"])
    out.print(slow)
    if s.lateness:
        out.print(f"real-time lateness: mean {s.lateness['mean_ms']:.3f} ms, max {s.lateness['max_ms']:.3f} ms, "
                  f"{s.lateness['late_steps']} of {s.lateness['steps']} steps late by > 1 ms", highlight=False)
    for ev in s.mode_switches:
        out.print(f"t={ev['t']:.4f} s step {ev['step']}: {ev['from']} → {ev['to']} ({ev['guard']}; {ev['values']})",
                  highlight=False)
    if s.async_age_ms:
        out.print("mean age of asynchronous values: " + ", ".join(f"{k} {v:.1f} ms" for k, v in s.async_age_ms.items()),
                  highlight=False)
    total = sum(s.server_waits.values())
    if total:
        shares = ", ".join(f"{100 * s.server_waits.get(k, 0) / total:.0f} % {label}" for k, label in
                           (("queued", "already queued"), ("polled", "caught while polling"), ("slept", "slept")))
        out.print(f"how the server had its {total:,} frames (waitStrategy {s.wait_strategy or '?'}): {shares}",
                  highlight=False)
    if s.dropped_frames:
        out.print("dropped frames: " + ", ".join(f"{k}: {v}" for k, v in s.dropped_frames.items()), highlight=False)


@app.command()
def plot(
    run_dir: Path,
    ports: Annotated[Optional[list[str]], typer.Argument(help="node.port columns (default: up to 8)")] = None,
    output: Annotated[Optional[Path], typer.Option("-o", "--output", help="PNG to write")] = None,
) -> None:
    """Draw recorded values over time with the mode switches marked, to a PNG."""
    from hycosim.server.report import RunDirError, plot_run

    try:
        path = plot_run(run_dir, ports or [], output or run_dir / "plot.png")
    except RunDirError as exc:
        err.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(2) from None
    out.print(f"wrote {path}", highlight=False)


def _monitor_credentials(endpoint: str, tls_ca: Path | None, password_file: Path | None) -> tuple[dict | None, str | None]:
    """A monitor's TLS settings and password (``status``, ``dashboard``); exit 2 naming what is wrong."""
    from hycosim.core.security import SecurityError, ca_settings, read_password

    if endpoint.startswith("tls/") and tls_ca is None:
        err.print(f"[red]error:[/red] {endpoint} is a TLS endpoint: give --tls-ca with the CA that signed "
                  "the server's certificate", highlight=False)
        raise typer.Exit(2)
    try:
        return ca_settings(tls_ca) if tls_ca else None, read_password(password_file) if password_file else None
    except SecurityError as exc:
        err.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(2) from None


@app.command()
def status(
    endpoint: str,
    project: Annotated[str, typer.Option(help="project name")] = "*",
    timeout: Annotated[float, typer.Option(min=0.1, max=3600.0, help="seconds to wait for an answer")] = 3.0,
    user: Annotated[Optional[str], typer.Option(help="user, when the server requires credentials")] = None,
    password_file: Annotated[Optional[Path], typer.Option(help="that user's password")] = None,
    tls_ca: Annotated[Optional[Path], typer.Option(help="CA certificate (PEM) for a tls/ endpoint")] = None,
) -> None:
    """Ask a running server who is attached."""
    from hycosim.core import json_text
    from hycosim.core.keys import ProjectKeys
    from hycosim.core.session import ConnectError, client_config, open_session

    endpoint = _endpoint("endpoint", endpoint)
    tls, password = _monitor_credentials(endpoint, tls_ca, password_file)
    try:
        session = open_session(client_config(endpoint, timeout_s=timeout, user=user, password=password, tls=tls),
                               endpoint)
    except ConnectError as exc:
        err.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(3) from None
    answers, busy = [], []
    try:
        for reply in session.get(ProjectKeys(project).status, timeout=timeout):
            if reply.ok is None:  # a server over its budget of answers says so (server.answer_budget)
                said = reply.err.payload.to_bytes()[:200].decode(errors="replace") if reply.err is not None else ""
                busy += [said] if said.startswith("busy: ") else []
            else:
                try:
                    answer = json_text.loads(reply.ok.payload.to_bytes())
                except ValueError:
                    continue  # not a hycosim server's answer (anyone may answer on the key)
                if _is_status(answer):
                    answers.append(answer)
    finally:
        session.close()
    if not answers and busy:
        shown = "".join(c for c in busy[0] if c.isprintable())  # anyone may answer on the key
        err.print(f"[red]error:[/red] the server on {endpoint} is {escape(shown)}", highlight=False)
        raise typer.Exit(3)
    if not answers:
        err.print(f"[red]error:[/red] no hycosim server answered on {endpoint} within {timeout:g} s", highlight=False)
        raise typer.Exit(3)
    for a in answers:
        out.print(f"{a['project']}: step {a['step']} t={a['t']:g} s mode={a['mode']}; "
                  f"attached {len(a['attached'])}/{len(a['expected'])}: {', '.join(a['attached'])}", highlight=False)


def _is_status(answer: object) -> bool:
    """Whether a reply on the status key reads as a hycosim server's (anyone may answer there)."""
    if not isinstance(answer, dict):
        return False
    number = (int, float)
    return (isinstance(answer.get("project"), str) and isinstance(answer.get("mode"), str)
            and type(answer.get("step")) is int and type(answer.get("t")) in number
            and all(isinstance(answer.get(k), list) and all(isinstance(n, str) for n in answer[k])
                    for k in ("attached", "expected")))


# The schema as shipped: beside this module, and named by the configs in the repository.
SCHEMA_FILE = Path(__file__).resolve().parent / "project.schema.json"


@app.command()
def dashboard(
    target: Annotated[str, typer.Argument(help="a run directory, or the endpoint of a running server")],
    port: Annotated[int, typer.Option(min=0, max=65535, help="the page's port (0: any free one)")] = 8050,
    host: Annotated[str, typer.Option(help="address to serve the page on")] = "127.0.0.1",
    project: Annotated[Optional[str], typer.Option(help="the project, when one endpoint serves several")] = None,
    user: Annotated[Optional[str], typer.Option(help="user, when the server requires credentials")] = None,
    password_file: Annotated[Optional[Path], typer.Option(help="that user's password")] = None,
    tls_ca: Annotated[Optional[Path], typer.Option(help="CA certificate (PEM) for a tls/ endpoint")] = None,
    retry: Annotated[float, typer.Option(min=0.05, max=3600.0,
                                         help="seconds between tries to reach a server that does not answer")] = 2.0,
    allow_origin: Annotated[Optional[list[str]], typer.Option(
        help="another site whose pages may open the feed (scheme://host[:port]): a page embedding the "
             "dashboard, a reverse proxy; repeatable")] = None,
) -> None:
    """Watch a running co-simulation, or look through a finished run, in a browser."""
    from hycosim.dashboard.app import bind, serve
    from hycosim.dashboard.origin import normal_origin
    from hycosim.server.report import RunDirError

    for origin in allow_origin or []:
        if normal_origin(origin) is None:
            err.print(f"[red]error:[/red] --allow-origin {escape(repr(origin))}: not an origin "
                      "(scheme://host\\[:port], http or https, no path)", highlight=False)
            raise typer.Exit(2)
    path = Path(target)
    if path.is_dir():
        from hycosim.dashboard.finished import FinishedRun

        try:
            source = FinishedRun(path)
        except RunDirError as exc:
            err.print(f"[red]error:[/red] {exc}", highlight=False)
            raise typer.Exit(2) from None
        closing = None
    else:
        from hycosim.dashboard.live import LiveFeed

        endpoint = _endpoint("endpoint", target)
        tls, password = _monitor_credentials(endpoint, tls_ca, password_file)
        source = LiveFeed(endpoint, project, user=user, password=password, tls=tls, retry_s=retry)
        source.start()
        closing = source.close
    try:
        sock = bind(host, port)
    except OSError as exc:
        err.print(f"[red]error:[/red] --port: cannot serve the page on {host}:{port} ({exc.strerror or exc})",
                  highlight=False)
        raise typer.Exit(2) from None
    shown = f"[{host}]" if ":" in host else host
    out.print(f"dashboard: http://{shown}:{sock.getsockname()[1]}/", highlight=False)
    sys.stdout.flush()  # a launcher reads the address from a pipe
    try:
        serve(source, sock, tuple(allow_origin or ()))
    finally:
        if closing is not None:
            closing()


@app.command()
def schema(
    output: Annotated[Optional[Path], typer.Option("-o", "--output", help="write it here (default: stdout)")] = None,
) -> None:
    """The JSON Schema of the project file: name it in a project with "$schema" and an editor
    checks and completes the file as you type."""
    from hycosim.core.config import project_json_schema

    text = json.dumps(project_json_schema(), indent=1) + "\n"
    if output is None:
        out.print(text, highlight=False, markup=False, end="")
        return
    output.write_text(text)
    out.print(f"{output}: the JSON Schema of hycosim's project file (a copy ships as {SCHEMA_FILE})", highlight=False)


@app.command("import")
def import_ssp(
    package: Path,
    output: Annotated[Path, typer.Option("-o", "--output", help="the project JSON to write (its FMUs go in a "
                                                                 "folder beside it)")] = Path("project.json"),
    side: Annotated[Optional[Path], typer.Option(help="JSON with what SSP has no word for: serverIP, events, "
                                                      "asynchronous nodes, coSimulation keys")] = None,
    step: Annotated[Optional[float], typer.Option(min=0.0, callback=_finite,
                                                  help="the macro step, when the package gives none")] = None,
    stop: Annotated[Optional[float], typer.Option(callback=_finite,
                                                  help="the stop time, when the package gives none")] = None,
) -> None:
    """Turn an SSP package into a project JSON to edit and keep: components become nodes,
    connections links, parameter bindings parameters, the default experiment coSimulation."""
    written = _from_ssp(package, output, side=side, step=step, stop=stop)
    loaded = _load(written)
    out.print(f"{written}: project {loaded.project.projectName!r}, {len(loaded.project.nodeLists)} nodes, "
              f"{len(loaded.routes)} routes (FMUs in {written.parent / (written.stem + '-fmus')})", highlight=False)


@app.command("export")
def export_ssp(
    file: Path,
    output: Annotated[Path, typer.Option("-o", "--output", help="the .ssp package to write")] = Path("system.ssp"),
) -> None:
    """Write a project whose nodes are all FMUs as an SSP 1.0 package (FMPy's simulate_ssp reads it)."""
    from hycosim.fmu_bridge.ssp import SspError, write_ssp

    loaded = _load(file)
    try:
        written = write_ssp(loaded, output)
    except SspError as exc:
        err.print(f"[red]error:[/red] {escape(str(exc))}", highlight=False)
        raise typer.Exit(2) from None
    out.print(f"{written}: {len(loaded.project.nodeLists)} components, {len(loaded.routes)} connections",
              highlight=False)


fmu_app = typer.Typer(no_args_is_help=True, help="Build bridge FMUs from a project; inspect FMUs.")
app.add_typer(fmu_app, name="fmu")


@fmu_app.command("build")
def fmu_build(
    file: Path,
    output: Annotated[Path, typer.Option("-o", "--output", help="folder for the .fmu files")] = Path("fmus"),
    node: Annotated[Optional[list[str]], typer.Option(help="only these nodes (repeatable)")] = None,
    server: Annotated[Optional[str], typer.Option(help="gateway HOST:PORT baked in as the default")] = None,
) -> None:
    """Write one native FMI 2.0 co-simulation bridge FMU per stepping node of the project."""
    from fmpy.validation import validate_fmu

    from hycosim.fmu_bridge.bridge_fmu import BridgeBuildError, build_bridge_fmus

    loaded = _load(file)
    if server is not None:
        server = _endpoint("--server", server, partial(parse_address, default_port=GATEWAY_PORT))
    unknown = [n for n in node or [] if n not in {x.nodeName for x in loaded.project.nodeLists}]
    if unknown:
        err.print(f"[red]error:[/red] {file}: no node named {', '.join(unknown)}", highlight=False)
        raise typer.Exit(2)
    try:
        built = build_bridge_fmus(loaded, output, server, node)
    except BridgeBuildError as exc:
        err.print(f"[red]error:[/red] {file}: {exc}", highlight=False)
        raise typer.Exit(2) from None
    for b in built:
        problems = validate_fmu(str(b.path))
        status = "valid" if not problems else "INVALID: " + "; ".join(problems)
        out.print(f"{b.path}  ({b.model_identifier}, {status})", highlight=False)
        if problems:
            raise typer.Exit(4)


@fmu_app.command("inspect")
def fmu_inspect(
    fmu: Path,
    config: Annotated[Optional[Path], typer.Option(help="a project JSON: show how a node's ports map")] = None,
    node: Annotated[Optional[str], typer.Option(help="the node of --config (default: the one naming this FMU)")] = None,
) -> None:
    """List an FMU's co-simulation capabilities and variables; with --config, the port mapping."""
    import fmpy

    from hycosim.fmu_bridge.fmu_loader import FmuError, check_platform, describe, map_driven, map_ports

    try:
        md = describe(fmu)
    except FmuError as exc:
        err.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(2) from None
    cs, me = md.coSimulation, md.modelExchange
    caps = Table(title=f"{fmu.name}: FMI {md.fmiVersion}, {md.modelName}")
    caps.add_column("capability")
    caps.add_column("value")
    caps.add_row("interfaces", ", ".join(["co-simulation"] * bool(cs) + ["Model Exchange (the node integrates it)"] * bool(me))
                 or "none")
    caps.add_row("platforms", ", ".join(fmpy.supported_platforms(str(fmu))) or "-")
    for label, element, attrs in (
            ("co-simulation", cs, ("canGetAndSetFMUstate", "canSerializeFMUstate", "canHandleVariableCommunicationStepSize",
                                   "needsExecutionTool", "hasEventMode", "canReturnEarlyAfterIntermediateUpdate")),
            ("Model Exchange", me, ("canGetAndSetFMUstate", "canSerializeFMUstate", "needsCompletedIntegratorStep"))):
        if element is None:
            continue
        caps.add_row(f"{label}: modelIdentifier", element.modelIdentifier)
        for attr in attrs:
            if hasattr(element, attr):
                caps.add_row(f"{label}: {attr}", str(bool(getattr(element, attr))))
    if me is not None:
        caps.add_row("continuous states, event indicators",
                     f"{md.numberOfContinuousStates or 0}, {md.numberOfEventIndicators or 0}")
    _print_table(caps)
    variables = Table(title="variables")
    for col in ("name", "causality", "variability", "type", "start", "unit"):
        variables.add_column(col)
    for v in md.modelVariables:
        variables.add_row(v.name, v.causality or "", v.variability or "", v.type, "" if v.start is None else str(v.start),
                          getattr(v, "unit", None) or "")
    _print_table(variables)
    if config is None:
        return
    loaded = _load(config)
    spec = None
    if node:
        try:
            spec = loaded.project.node(node)
        except KeyError:
            err.print(f"[red]error:[/red] {config}: no node named {node!r}", highlight=False)
            raise typer.Exit(2) from None
    else:
        spec = next((n for n in loaded.project.nodeLists if n.fmu and loaded.resolve(n.fmu) == fmu.resolve()), None)
        if spec is None:
            err.print(f"[red]error:[/red] {config}: no node names {fmu}; pick one with --node", highlight=False)
            raise typer.Exit(2)
    try:
        check_platform(fmu, md, spec.nodeName)
        inputs, outputs = map_ports(md, spec, fmu)
        driven = map_driven(md, spec, fmu)
    except FmuError as exc:
        err.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(2) from None
    mapping = Table(title=f"node {spec.nodeName!r} → {fmu.name}")
    for col in ("port", "direction", "FMU variable", "value reference", "type"):
        mapping.add_column(col)
    for direction, ports in (("input", inputs), ("output", outputs)):
        for m in ports:
            mapping.add_row(m.port, direction, m.variable, str(m.vr), m.type)
    if driven is not None:
        mapping.add_row("(driven flag)", "input", driven.name, str(driven.valueReference), driven.type)
    _print_table(mapping)


scene_app = typer.Typer(no_args_is_help=True, help="The robot scene: reachability, FMUs.")
app.add_typer(scene_app, name="scene")


@scene_app.command("reach")
def scene_reach(
    file: Path,
    node: Annotated[str, typer.Option(help="the robot node whose parameters place base and rod")] = "robot",
    output: Annotated[Optional[Path], typer.Option("-o", "--output", help="PNG to write")] = None,
) -> None:
    """Which part of the rod's swing the robot can reach from its base placement: table and PNG."""
    from hycosim.clients.robot.node import scene_parameter_problems, scene_params
    from hycosim.clients.robot.reach import analyse_reach, plot_reach

    loaded = _load(file)
    try:
        spec = loaded.project.node(node)
    except KeyError:
        err.print(f"[red]error:[/red] {file}: no node named {node!r} (use --node)", highlight=False)
        raise typer.Exit(2) from None
    wrong = scene_parameter_problems(spec.parameters)
    if wrong:
        err.print(f"[red]error:[/red] {escape(str(file))}: node {node!r}: {escape('; '.join(wrong))}", highlight=False)
        raise typer.Exit(2)
    report = analyse_reach(scene_params(spec.parameters))
    table = Table(title=f"reach of {node!r} over the rod's swing")
    for col in ("rod angle (°)", "grasp point (m)", "reachable", "IK error (mm)", "A1…A6 (°)", "limit margin (°)"):
        table.add_column(col)
    for p in report.points:
        table.add_row(f"{p.angle_deg:+.1f}", "({:.3f}, {:.3f}, {:.3f})".format(*p.position),
                      "yes" if p.reachable else "[red]no[/red]", f"{p.position_error_mm:.2f}",
                      " ".join(f"{v:.0f}" for v in p.q_deg), f"{p.limit_margin_deg:.0f}")
    out.print(table)
    rng = report.reachable_range()
    out.print(("reachable from {:+.1f}° to {:+.1f}°".format(*rng) if rng else "no part of the swing is reachable")
              + "; share of the swing reachable: " + ", ".join(
                  f"±{a}°: {100 * report.fraction_of_swing(a):.0f} %" for a in (30, 40, 50, 60)), highlight=False)
    png = plot_reach(report, output or Path(f"reach-{loaded.name}.png"))
    out.print(f"wrote {png}", highlight=False)


@scene_app.command("fmus")
def scene_fmus(output: Annotated[Path, typer.Option("-o", "--output")] = Path("build/fmus")) -> None:
    """Build the rod and robot-scene FMUs (pythonfmu) into a folder."""
    from fmpy.validation import validate_fmu

    from hycosim.clients.scene_fmus import build_scene_fmus

    try:
        built = build_scene_fmus(output)
    except OSError as exc:
        err.print(f"[red]error:[/red] {output}: cannot write the FMUs there ({exc.strerror or exc})", highlight=False)
        raise typer.Exit(2) from None
    for name, path in built.items():
        problems = validate_fmu(str(path))
        out.print(f"{name}: {path} ({'valid' if not problems else 'INVALID: ' + '; '.join(problems)})", highlight=False)
        if problems:
            raise typer.Exit(4)


@app.command()
def camera(
    source: Annotated[str, typer.Option(help="'emulated', a video file, or a camera device index")] = "emulated",
    annotate: Annotated[Optional[Path], typer.Option(help="write the frames with the detected rod drawn, .mp4 or .avi")] = None,
    seconds: Annotated[float, typer.Option(min=0.0, callback=_finite,
                                           help="how much to process (emulated: simulated seconds)")] = 3.0,
    calibration: Annotated[Optional[Path], typer.Option(help="calibration JSON (real sources)")] = None,
    initial_angle: Annotated[float, typer.Option(callback=_finite,
                                                 help="emulated rod's release angle, degrees")] = 45.0,
    noise: Annotated[float, typer.Option(min=0.0, callback=_finite,
                                         help="emulated image noise σ (grey levels)")] = 25.0,
    fps: Annotated[float, typer.Option(min=1.0, max=1000.0, help="emulated frame rate")] = 60.0,
) -> None:
    """Run the camera node alone: detect the rod in each frame and summarise (and annotate)."""

    import cv2
    import numpy as np

    from hycosim.clients.camera.calibration import Calibration, CalibrationError
    from hycosim.clients.camera.detect import RodDetector, annotate as draw
    from hycosim.clients.camera.emulated import CameraSetup, EmulatedRodCamera
    from hycosim.clients.camera.sources import CameraError, DeviceSource, VideoFileSource, device_number
    from hycosim.clients.camera.tracker import Tracker
    from hycosim.clients.rod.model import RodParams

    try:
        if source == "emulated":
            emu = EmulatedRodCamera(RodParams(initial_angle=math.radians(initial_angle)),
                                    CameraSetup(noise_sigma=noise, fps=fps))
            frames = emu.frames_until(seconds)
            cal = emu.calibration
        else:
            if calibration is None:
                err.print("[red]error:[/red] a real source needs --calibration FILE", highlight=False)
                raise typer.Exit(2)
            cal = Calibration.load(calibration)
            device = device_number(source)
            src = DeviceSource(device) if device is not None else VideoFileSource(Path(source))
            frames = []
            for frame in src.frames():
                if frame.t > seconds:
                    break
                frames.append(frame)
            src.close()
    except (CameraError, CalibrationError) as exc:
        err.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(3) from None
    detector, tracker = RodDetector(cal), Tracker()
    writer = None
    errors, detected, t_detect = [], 0, 0.0
    for frame in frames:
        start = time.perf_counter()
        found = detector.detect(frame.image)
        t_detect += time.perf_counter() - start
        m = tracker.update(frame.t, found)
        if m is not None:
            detected += 1
            if not math.isnan(frame.true_angle):
                errors.append(abs(math.degrees(m.angle - frame.true_angle)))
        if annotate is not None and frame.image is not None:
            if writer is None:
                h, w = frame.image.shape[:2]
                fourcc = cv2.VideoWriter_fourcc(*("mp4v" if annotate.suffix == ".mp4" else "MJPG"))
                writer = cv2.VideoWriter(str(annotate), fourcc, fps if source == "emulated" else 30.0, (w, h))
                if not writer.isOpened():  # OpenCV does not raise: it writes nothing
                    err.print(f"[red]error:[/red] {annotate}: cannot write a video there (a missing folder, "
                              "or a suffix other than .mp4 or .avi?)", highlight=False)
                    raise typer.Exit(2)
            writer.write(draw(frame.image, found, cal, f"t={frame.t:.3f}s"))
    if writer is not None:
        writer.release()
    usable = sum(f.image is not None for f in frames)
    out.print(f"{len(frames)} frames ({len(frames) - usable} dropped), {detected} confident detections, "
              f"detection {usable / t_detect if t_detect else 0:,.0f} frames/s", highlight=False)
    if errors:
        out.print(f"angle error against the emulated rod: mean {np.mean(errors):.3f}°, max {np.max(errors):.3f}°",
                  highlight=False)
    if annotate is not None:
        out.print(f"wrote {annotate}", highlight=False)


@app.command()
def train(
    output: Annotated[Path, typer.Option("-o", "--output", help="folder for checkpoints and the learning curve")] = Path("runs/train"),
    episodes: Annotated[int, typer.Option(min=0, help="DDPG episodes after the demonstrations")] = 200,
    demos: Annotated[int, typer.Option(min=0, help="reference-controller episodes to learn from")] = 100,
    eval_every: Annotated[int, typer.Option(min=1, help="evaluate every N episodes")] = 20,
    eval_trials: Annotated[int, typer.Option(min=1, help="evaluation episodes per release angle")] = 10,
    select_trials: Annotated[int, typer.Option(min=0, help="episodes per angle to choose best.pt on at the end "
                                               "(0: the periodic evaluations choose)")] = 50,
    seed: Annotated[int, typer.Option(min=0, max=2**31 - 1, help="seed of the networks, the noise and the episodes")] = 0,
    ship: Annotated[Optional[Path], typer.Option(help="also write a small copy of the best checkpoint here")] = None,
) -> None:
    """Train the DDPG grasp policy (demonstrations, behaviour cloning, DDPG); resumes from OUTPUT/last.pt."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from hycosim.clients.policy.ddpg import CheckpointError
    from hycosim.clients.policy.train import TrainConfig, train as run_training

    config = TrainConfig(demo_episodes=demos, episodes=episodes, eval_every=eval_every, eval_trials=eval_trials,
                         select_trials=select_trials, seed=seed)
    config.ddpg.seed = seed
    stats = {"returns": [], "successes": []}
    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TextColumn("{task.fields[info]}"), TimeElapsedColumn(), console=err) as progress:
        demo_task = progress.add_task("demonstrations", total=demos, info="")
        dagger_task = progress.add_task("DAgger", total=config.dagger_rounds * config.dagger_episodes, info="")
        rollout_task = progress.add_task("critics on the cloned policy", total=None, info="")
        task = progress.add_task("DDPG", total=episodes, info="")
        select_task = progress.add_task("choosing best.pt", total=None, info="")

        def report(d: dict) -> None:
            if d["phase"] == "demonstrations":
                progress.update(demo_task, completed=d["done"])
            elif d["phase"] == "dagger":
                progress.update(dagger_task, completed=d["done"])
            elif d["phase"] == "select":
                progress.update(select_task, completed=d["done"], total=d["total"])
            elif d["phase"] == "rollouts":
                progress.update(rollout_task, completed=d["done"], total=d["total"])
            elif d["phase"] == "ddpg":
                stats["returns"].append(d["return"])
                stats["successes"].append(d["success"])
                last = stats["returns"][-20:]
                rate = sum(stats["successes"][-20:]) / len(stats["successes"][-20:])
                progress.update(task, completed=d["episode"],
                                info=f"mean return {sum(last) / len(last):7.1f}  success {100 * rate:3.0f} %")
            elif d["phase"] in ("eval", "pretrained"):
                text = ", ".join(f"{k}°: {100 * v['success']:.0f} % ({100 * v['precise']:.0f} % ≤ 3 mm)"
                                 for k, v in d["per_angle"].items())
                progress.console.print(f"evaluation after {d.get('episode', 0)} episodes: {text}", highlight=False)

        try:
            result = run_training(output, config, report)
        except KeyboardInterrupt as exc:
            progress.stop()
            saved = output / "last.pt"
            err.print(f"{signals.describe(exc)}; " + (
                f"the same command resumes from {saved}" if saved.exists() else
                "no checkpoint yet (the first is written after the cloning phase)"), highlight=False)
            raise typer.Exit(signals.exit_code(exc)) from None
        except (ValueError, CheckpointError) as exc:
            err.print(f"[red]error:[/red] {exc}", highlight=False)
            raise typer.Exit(2) from None
    if ship is not None:
        from hycosim.clients.policy.ddpg import strip_checkpoint

        strip_checkpoint(output / "best.pt", ship)
    for when, e in (result.get("critic_error") or {}).items():
        out.print(f"critics on held-out rollouts of the cloned policy ({when.replace('_', ' ')}): mean error "
                  f"{e['mae']:.1f} on returns of mean {e['return_mean']:.1f} ({100 * e['relative']:.0f} %)",
                  highlight=False)
    if result.get("selected_episode") is not None:
        out.print(f"best.pt: the policy after {result['selected_episode']} DDPG episodes, chosen on "
                  f"{config.select_trials} fresh episodes per angle among the leading evaluations", highlight=False)
    out.print(f"best mean evaluation success {100 * result['best_mean_success']:.0f} % "
              f"({100 * result['best_mean_precise']:.0f} % within 3 mm) in "
              f"{result['trained_s']:.0f} s; checkpoints and learning_curve.png in {output}", highlight=False)


@app.command()
def evaluate(
    checkpoints: Annotated[list[Path], typer.Argument(help="policy checkpoints (.pt) to evaluate on the same episodes")],
    trials: Annotated[int, typer.Option(min=1, help="episodes per release angle")] = 100,
    workers: Annotated[int, typer.Option(min=1, max=256, help="processes to spread the episodes over")] = 2,
    seed: Annotated[int, typer.Option(min=0, max=2**31 - 1,
                                      help="first episode seed (the release phase and side are random)")] = 10_000,
    json_out: Annotated[Optional[Path], typer.Option("--json", help="also write the figures here")] = None,
) -> None:
    """Evaluate policy checkpoints in the training environment: per release angle, success, grasps
    within 3 mm (with 95 % intervals), collisions, time to grasp and distance."""
    import json

    from hycosim.clients.policy.ddpg import CheckpointError, load_policy
    from hycosim.clients.policy.train import evaluate_checkpoint

    def save(figures: dict) -> None:  # after each checkpoint: what was measured stays on disk
        if json_out is None:
            return
        try:
            json_out.write_text(json.dumps(figures, indent=1))
        except OSError as exc:
            err.print(f"[red]error:[/red] --json: cannot write {json_out} ({exc.strerror or exc})", highlight=False)
            raise typer.Exit(2) from None

    figures: dict = {}
    save(figures)  # a file that cannot be written is named before the episodes, not after
    for path in checkpoints:
        try:
            meta = load_policy(path).meta
        except CheckpointError as exc:
            err.print(f"[red]error:[/red] {exc}", highlight=False)
            raise typer.Exit(2) from None
        figures[str(path)] = {"episodes_trained": meta.get("episodes"),
                              "per_angle": evaluate_checkpoint(path, trials, workers, seed)}
        save(figures)
        out.print(f"{path} (DDPG episodes {meta.get('episodes')}), {trials} episodes per angle:", highlight=False)
        for angle, v in figures[str(path)]["per_angle"].items():
            lo, hi = v["success_95"]
            grasp = f"{v['grasp_time_s']:.2f} s" if v["grasp_time_s"] is not None else "-"
            out.print(f"  {angle:>3}°  success {100 * v['success']:5.1f} % ({100 * lo:.0f}–{100 * hi:.0f})  "
                      f"≤ 3 mm {100 * v['precise']:5.1f} %  collisions {100 * v['collision']:4.1f} %  "
                      f"time to grasp {grasp}  distance {v['distance_mm']:.2f} mm", highlight=False)


krl_app = typer.Typer(no_args_is_help=True, help="KUKA EthernetKRL: export a run's path; an emulated controller.")
app.add_typer(krl_app, name="krl")


@krl_app.command("export")
def krl_export(run_dir: Path, output: Annotated[Path, typer.Option("-o", "--output")] = Path("krl")) -> None:
    """Write the EKI configuration, the KRL program (Table 1) and the XML frame stream of a run."""
    from hycosim.clients.krl.export import ExportError, export

    try:
        files = export(run_dir, output)
    except ExportError as exc:
        err.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(2) from None
    for kind, path in files.items():
        out.print(f"{kind}: {path}", highlight=False)


@krl_app.command("controller")
def krl_controller(
    eki: Annotated[Path, typer.Option(help="the EKI configuration (port, RECEIVE elements)")],
    port: Annotated[Optional[int], typer.Option(min=1, max=65535, help="override the EKI file's port")] = None,
    host: Annotated[str, typer.Option(help="address to listen on")] = "127.0.0.1",
    length: Annotated[float, typer.Option(min=0.05, callback=_finite, help="physical rod length (m)")] = 0.6,
    angle: Annotated[float, typer.Option(callback=_finite, help="physical rod release angle (deg)")] = 40.0,
    programs: Annotated[int, typer.Option(min=0, help="stop after this many programs (0: run until stopped)")] = 0,
) -> None:
    """Listen as the robot's EKI endpoint and execute programs against the emulated physical rod."""

    from hycosim.clients.krl.controller import EmulatedController
    from hycosim.clients.krl.eki import EkiConfig, EkiError
    from hycosim.clients.rod.model import RodParams

    try:
        config = EkiConfig.parse(eki.read_bytes(), str(eki))
    except OSError as exc:
        err.print(f"[red]error:[/red] {eki}: cannot read ({exc.strerror or exc})", highlight=False)
        raise typer.Exit(2) from None
    except EkiError as exc:
        err.print(f"[red]error:[/red] {exc}", highlight=False)
        raise typer.Exit(2) from None
    try:
        controller = EmulatedController(config, RodParams(length=length, initial_angle=math.radians(angle)),
                                        host=host, port=port)
    except OSError as exc:
        err.print(f"[red]error:[/red] cannot listen on {Address(host, port or config.port)} ({exc.strerror or exc})",
                  highlight=False)
        raise typer.Exit(3) from None
    out.print(f"emulated KUKA controller listening on {Address(host, controller.address[1])} ({eki.name})",
              highlight=False)
    try:
        while programs == 0 or len(controller.results) < programs:
            conn, peer = controller.listener.accept()
            with conn:
                result = controller.handle(conn, str(peer))
            if result is not None:
                out.print(f"program ended: {'grasped' if result.grasped else 'missed'}, error "
                          f"{result.grasp_error_mm if result.grasp_error_mm is not None else '-'} mm, "
                          f"{result.frames} frames, {len(result.rejected)} rejected", highlight=False)
            else:
                err.print(f"rejected: {controller.errors[-1]}", highlight=False)
    finally:  # Ctrl-C, SIGTERM or SIGHUP: main() ends with the signal's status
        controller.stop()


@app.command()
def trials(
    angles: Annotated[str, typer.Option(help="initial angles in degrees, each in (0, 90): --angles 30 40 50 60")] = "30,40,50,60",
    n: Annotated[int, typer.Option("--trials", min=1, help="trials per angle")] = 20,
    correction: Annotated[bool, typer.Option("--correction/--no-correction", help="camera correction of the twin")] = True,
    driver: Annotated[str, typer.Option(help="'policy' (pretrained DDPG) or 'reference' (scripted)")] = "policy",
    nodes: Annotated[str, typer.Option(help="the rod and the robot scene as 'fmu' (the FMUs `hycosim scene fmus` "
                                            "builds, built when missing) or as 'python' nodes")] = "fmu",
    output: Annotated[Path, typer.Option("-o", "--output")] = Path("runs/trials"),
) -> None:
    """Rerun the paper's trials: co-simulation, EthernetKRL export, emulated controller, Table 2."""
    from hycosim.trials import NODE_KINDS, PAPER, TrialsInterrupted, run_trials, summarise, write_outputs

    if driver not in ("policy", "reference"):
        err.print("[red]error:[/red] --driver is 'policy' or 'reference'", highlight=False)
        raise typer.Exit(2)
    if nodes not in NODE_KINDS:
        err.print(f"[red]error:[/red] --nodes is {' or '.join(map(repr, NODE_KINDS))}", highlight=False)
        raise typer.Exit(2)
    try:
        angle_list = [float(a) for a in angles.replace(",", " ").split()]
    except ValueError:
        err.print(f"[red]error:[/red] --angles {angles!r}: give numbers in degrees", highlight=False)
        raise typer.Exit(2) from None
    outside = [a for a in angle_list if not 0.0 < a < 90.0]
    if not angle_list or outside:
        # The rod is released from rest on one side, below the horizontal (the paper: 30° to 60°).
        err.print(f"[red]error:[/red] --angles {angles!r}: "
                  + (f"{', '.join(f'{a:g}°' for a in outside)} outside (0°, 90°)" if outside else "no angle given"),
                  highlight=False)
        raise typer.Exit(2)
    def progress(r) -> None:
        if r.error:
            err.print(f"{r.angle:g}° #{r.trial}: [red]not run[/red]: {r.error}", highlight=False)
            return
        err.print(f"{r.angle:g}° #{r.trial}: {'grasped' if r.success else 'missed'}"
                  + (f", {r.grasp_error_mm:.1f} mm, {r.execution_time_s:.2f} s" if r.success else ""), highlight=False)

    interrupted = None
    try:
        results = run_trials(angle_list, n, output, correction, driver, progress, nodes)
    except TrialsInterrupted as exc:
        # Ctrl-C again must not cut short the table and files of the finished trials (a second or two).
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        interrupted, results = exc, exc.results
        if not results:
            err.print(f"[red]error:[/red] {exc}; nothing to tabulate", highlight=False)
            raise typer.Exit(130) from None
    csv_path, png = write_outputs(results, output)
    table = Table(title=f"grasping trials ({'with' if correction else 'without'} camera correction, {driver}, "
                        f"rod and robot as {'FMUs' if nodes == 'fmu' else 'Python nodes'}): "
                        "grasp distance error, execution time, success")
    for col in ("angle", "mm", "s", "success", "paper mm", "paper s", "paper %"):
        table.add_column(col, no_wrap=True)
    for angle, row in summarise(results).items():
        p = PAPER.get(int(angle), (float("nan"),) * 3)
        table.add_row(f"{angle:g}°", f"{row['error_mm']:.1f}", f"{row['time_s']:.2f}",
                      f"{row['success_pct']:.0f} % of {row['trials']}", f"{p[0]}", f"{p[1]}", f"{p[2]}")
    out.print(table)
    out.print(f"wrote {csv_path} and {png}", highlight=False)
    if interrupted is not None:
        err.print(f"[red]error:[/red] {interrupted} of {len(angle_list) * n}: the table holds those", highlight=False)
        raise typer.Exit(signals.exit_code(interrupted.stop))
    failed = [r for r in results if r.error]
    if failed:
        err.print(f"[red]error:[/red] {len(failed)} of {len(results)} trials could not be run (counted as missed): "
                  + "; ".join(f"{r.angle:g}° #{r.trial}" for r in failed), highlight=False)
        raise typer.Exit(3)


def _is_option(arg: str) -> bool:
    # "-o" is an option; "-5" is a (negative) angle, left for trials to refuse.
    return arg.startswith("-") and not arg[1:2].isdigit()


def _join_multi_value_options(argv: list[str]) -> list[str]:
    # `--angles 30 40 50 60` as the paper's trials are written; click options take one value.
    out, i = [], 0
    while i < len(argv):
        out.append(argv[i])
        if argv[i] == "--angles":
            values = []
            while i + 1 < len(argv) and not _is_option(argv[i + 1]):
                i += 1
                values.append(argv[i])
            out.append(",".join(values))
        i += 1
    return out


def main() -> None:
    """Console entry point."""
    import faulthandler

    from hycosim.core.session import prefer_shared_runtime

    # A model that crashes in native code (an FMU's binary, an extension) kills the process
    # without a word from Python; the fault handler at least prints the stack it was at.
    faulthandler.enable()
    heard: list[int] = []  # the stop signals that came
    signals.raise_on_stop(heard)  # SIGTERM and SIGHUP (a supervisor, a closed terminal) are ways out like Ctrl-C
    prefer_shared_runtime()  # before any session opens; the server and nodes it starts inherit it
    try:
        app(args=_join_multi_value_options(sys.argv[1:]), prog_name="hycosim")
    except SystemExit as exc:
        # Typer ends a command a stop signal interrupted with 130 whatever the signal; a
        # supervisor's SIGTERM (143) or a closed terminal's SIGHUP (129) is told apart, as
        # the server, the nodes and the launcher tell it.
        stop = signals.stop_behind(exc) if exc.code == 130 else None
        if stop is not None:
            sys.exit(signals.exit_code(stop))
        raise
    except Exception as exc:
        if heard:  # Ctrl-C while MuJoCo's or torch's extension initialised surfaces as an ImportError
            stop = signals.Stopped(heard[0])
            err.print(signals.describe(stop), highlight=False)
            sys.exit(signals.exit_code(stop))
        if not isinstance(exc, OSError) or exc.filename is None:
            raise
        # The last resort for a file a command could not read or write (an output folder
        # that cannot be made, a PNG path in a missing folder): name it instead of a traceback.
        err.print(f"[red]error:[/red] {exc.filename}: {exc.strerror or exc}", highlight=False)
        sys.exit(2)


if __name__ == "__main__":
    main()
