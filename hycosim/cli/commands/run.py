"""Commands that run a co-simulation or ask a running one: server, node, run, status."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from hycosim.cli.extras import require_extra
from hycosim.cli.options import SspStep, SspStop, checked_endpoint, finite, monitor_credentials
from hycosim.cli.output import end_process, err, fail, out, print_summary, say_outcome, warn
from hycosim.cli.options import RecordFormat, ScenarioFile
from hycosim.cli.projects import load, project_file, scenario_of
from hycosim.core.signals import ignore_stops

app = typer.Typer()


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
    scenario: ScenarioFile = None,
    record: RecordFormat = None,
) -> None:
    """Run the relay server for one co-simulation (Zenoh nodes and bridge FMUs)."""
    from hycosim.master.main import serve

    loaded = load(file)
    actions = scenario_of(scenario, loaded)
    code, rdir, message = serve(loaded, listen=listen, runs_dir=runs_dir, run_dir=run_dir,
                                progress_jsonl=progress_jsonl, gateway=gateway, resume=resume, scenario=actions,
                                record=record)
    if code:
        say_outcome(err, message + (f"\n  results so far: {rdir}" if rdir else ""), error=True)
    elif not progress_jsonl:
        say_outcome(out, f"{message}; results in {rdir}")
    end_process(code)


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
    from hycosim.node.main import run_node

    loaded = load(file)
    code, message = run_node(loaded, name, connect, log_file, password_file)
    say_outcome(err if code else out, message, error=bool(code))
    end_process(code)


@app.command()
def run(
    file: Path,
    listen: Annotated[Optional[str], typer.Option(help="endpoint for the server (default: a free loopback port)")] = None,
    runs_dir: Annotated[Path, typer.Option(help="where run directories are made")] = Path("runs"),
    progress: Annotated[bool, typer.Option(help="show the progress bar")] = True,
    restarts: Annotated[int, typer.Option(min=0, help="how often a node process that dies before the start (or, "
                                                       "with checkpoints, during the run) is started again")] = 3,
    resume: Annotated[Optional[Path], typer.Option(help="go on with the run in this directory (its server died) "
                                                       "from its last checkpoint")] = None,
    dashboard: Annotated[bool, typer.Option(help="watch the run in a browser (hycosim dashboard)")] = False,
    dashboard_port: Annotated[int, typer.Option(min=0, max=65535, help="the dashboard's port on 127.0.0.1")] = 8050,
    in_process: Annotated[Optional[bool], typer.Option("--in-process/--processes", help="the master and every node "
                          "in this process, no sockets (default: coSimulation.transport)", show_default=False)] = None,
    step: SspStep = None,
    stop: SspStop = None,
    scenario: ScenarioFile = None,
    record: RecordFormat = None,
) -> None:
    """Run the server and every node as local processes on loopback, or all in this process
    (FILE: a project JSON or an SSP package)."""
    from hycosim.transport.security import SecurityError, router_security
    from hycosim.embedded import run_embedded

    file = project_file(file, step, stop)
    loaded = load(file)
    actions = scenario_of(scenario, loaded)
    if (record or loaded.project.recording.format) == "parquet":
        require_extra("parquet", "recording as Parquet")
    _refuse_unfit_nodes(loaded)
    if in_process is None:
        in_process = loaded.project.coSimulation.transport == "inprocess"
    if in_process:
        _run_in_process(loaded, runs_dir, progress, listen=listen, resume=resume, dashboard=dashboard,
                        scenario=actions, record=record)
        return
    listen = checked_endpoint("--listen", listen) if listen else None
    if resume is not None and not (resume / "meta.json").is_file():
        fail(f"--resume: {resume} is not a run directory (no meta.json)")
    if dashboard:
        require_extra("dashboard", "hycosim run --dashboard")
    if dashboard and loaded.project.security is not None and loaded.project.security.credentials:
        fail("--dashboard: this project's server requires credentials; attach a dashboard "
             "with its own: hycosim dashboard ENDPOINT --user NAME --password-file FILE")
    try:
        # The server reads these again; read here, a missing file is named before a run directory is made.
        router_security(loaded, listen or "")
    except SecurityError as exc:
        fail(str(exc))
    result = run_embedded(loaded, file, listen=listen, runs_dir=runs_dir, console=err, show_progress=progress,
                          restarts=restarts, resume=resume, dashboard_port=dashboard_port if dashboard else None,
                          scenario_file=scenario, record=record)
    if result.code >= 128:
        ignore_stops()  # a Ctrl-C pressed twice: the run is over, say so
    for line in result.warnings:
        warn(line)
    if result.code:
        say_outcome(err, f"{result.message}\n  results so far: {result.run_dir}", error=True)
        raise typer.Exit(result.code)
    _print_summary(result.run_dir)


def _refuse_unfit_nodes(loaded) -> None:
    """End the command (exit 2, as validate) on a node that cannot run however often it is
    started: a model that is not there (or whose extra is missing), a missing FMU file, an FMU
    whose model description already shows that it cannot run (a port on an array of another
    shape, clocks, a parameter it lacks). Named before a run directory is made, not by the
    node's process after the launch; reads model descriptions only, imports no model."""
    from hycosim.cli.projects import refuse_unfit_user_code
    from hycosim.node.loader import NodeLoadError, check_node, locate_node

    refuse_unfit_user_code(loaded.path, loaded)
    for spec in loaded.project.nodeLists:
        try:
            locate_node(spec, loaded.resolve("."))
            if spec.fmu and not (spec.replay or spec.asynchronous):
                check_node(spec, loaded.resolve("."), loaded.project.coSimulation)
        except NodeLoadError as exc:
            fail(f"{loaded.path}: {exc}")
    if any(action.parameter is not None for action in loaded.project.scenario):
        from hycosim.cli.commands.project import _refuse_untunable

        _refuse_untunable(loaded.path, loaded)


def _run_in_process(loaded, runs_dir: Path, progress: bool, *, listen: Optional[str], resume: Optional[Path],
                    dashboard: bool, scenario: list | None = None, record: str | None = None) -> None:
    from hycosim.embedded import run_progress
    from hycosim.inprocess import CannotHost, check_hostable, run_in_process

    for option, given in (("--listen", listen), ("--resume", resume), ("--dashboard", dashboard)):
        if given:  # each needs a network or processes an in-process run has not
            fail(f"{option} is for a run in processes; an in-process run has no server to attach to or go on "
                 f"with (run without --in-process)")
    try:
        check_hostable(loaded)
    except CannotHost as exc:
        fail(str(exc))
    bar, show = run_progress(loaded, err, progress)
    with bar:
        code, run_dir, message = run_in_process(loaded, runs_dir=runs_dir, on_progress=show, scenario=scenario,
                                                record=record)
    if code:
        fail(message, code, [f"results so far: {run_dir}"] if run_dir else [])
    _print_summary(run_dir)


def _print_summary(run_dir: Path) -> None:
    """The summary of a finished run; exit 3 naming the folder where its files cannot be read
    (moved or removed while the run wrote them)."""
    from hycosim.master.report import RunDirError, summarise

    try:
        summary = summarise(run_dir)
    except RunDirError as exc:
        fail(f"the run ended, but its results cannot be read: {exc} (was the folder moved or removed while "
             "the run wrote it?)", 3)
    print_summary(summary)


@app.command()
def status(
    endpoint: str,
    project: Annotated[str, typer.Option(help="project name")] = "*",
    timeout: Annotated[float, typer.Option(min=0.1, max=3600.0, callback=finite,
                                           help="seconds to wait for an answer")] = 3.0,
    user: Annotated[Optional[str], typer.Option(help="user, when the server requires credentials")] = None,
    password_file: Annotated[Optional[Path], typer.Option(help="that user's password")] = None,
    tls_ca: Annotated[Optional[Path], typer.Option(help="CA certificate (PEM) for a tls/ endpoint")] = None,
) -> None:
    """Ask a running server who is attached."""
    from hycosim.core import json_text
    from hycosim.transport.keys import ProjectKeys
    from hycosim.transport.session import ConnectError, client_config, open_session

    endpoint = checked_endpoint("endpoint", endpoint)
    tls, password = monitor_credentials(endpoint, tls_ca, password_file)
    try:
        session = open_session(client_config(endpoint, timeout_s=timeout, user=user, password=password, tls=tls),
                               endpoint)
    except ConnectError as exc:
        fail(str(exc), 3)
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
        fail(f"the server on {endpoint} is {shown}", 3)
    if not answers:
        fail(f"no hycosim server answered on {endpoint} within {timeout:g} s", 3)
    for a in answers:
        waiting = [n for n in a["expected"] if n not in a["attached"]]
        who = (f": {', '.join(a['attached'])}" if a["attached"] else "") + (
            f"; waiting for {', '.join(waiting)}" if waiting else "")
        out.print(f"{a['project']}: step {a['step']} t={a['t']:g} s mode={a['mode']}; "
                  f"attached {len(a['attached'])}/{len(a['expected'])}{who}", highlight=False, markup=False)


def _is_status(answer: object) -> bool:
    """Whether a reply on the status key reads as a hycosim server's (anyone may answer there)."""
    if not isinstance(answer, dict):
        return False
    number = (int, float)
    return (isinstance(answer.get("project"), str) and isinstance(answer.get("mode"), str)
            and type(answer.get("step")) is int and type(answer.get("t")) in number
            and all(isinstance(answer.get(k), list) and all(isinstance(n, str) for n in answer[k])
                    for k in ("attached", "expected")))
