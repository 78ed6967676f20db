"""Commands on results: report and plot a run directory, the dashboard (a run live or finished)."""

from __future__ import annotations

import json
import sys
from dataclasses import asdict
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.table import Table

from hycosim.cli.extras import require_extra
from hycosim.cli.options import checked_endpoint, finite, monitor_credentials
from hycosim.cli.output import fail, out, print_summary

app = typer.Typer()


@app.command()
def report(
    run_dir: Path,
    as_json: Annotated[bool, typer.Option("--json", help="print the summary as JSON")] = False,
) -> None:
    """Summarise a run: rate, who held the barrier, slowest steps, lateness, mode switches."""
    from hycosim.master.report import RunDirError, summarise

    try:
        s = summarise(run_dir)
    except RunDirError as exc:
        fail(str(exc))
    if as_json:
        out.print_json(json.dumps(asdict(s)))
        return
    print_summary(s)
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
    require_extra("plot", "hycosim plot")
    from hycosim.master.report import RunDirError, plot_run

    try:
        path = plot_run(run_dir, ports or [], output or run_dir / "plot.png")
    except RunDirError as exc:
        fail(str(exc))
    out.print(f"wrote {path}", highlight=False)


@app.command()
def dashboard(
    target: Annotated[str, typer.Argument(help="a run directory, or the endpoint of a running server")],
    port: Annotated[int, typer.Option(min=0, max=65535, help="the page's port (0: any free one)")] = 8050,
    host: Annotated[str, typer.Option(help="address to serve the page on")] = "127.0.0.1",
    project: Annotated[Optional[str], typer.Option(help="the project, when one endpoint serves several")] = None,
    user: Annotated[Optional[str], typer.Option(help="user, when the server requires credentials")] = None,
    password_file: Annotated[Optional[Path], typer.Option(help="that user's password")] = None,
    tls_ca: Annotated[Optional[Path], typer.Option(help="CA certificate (PEM) for a tls/ endpoint")] = None,
    retry: Annotated[float, typer.Option(min=0.05, max=3600.0, callback=finite,
                                         help="seconds between tries to reach a server that does not answer")] = 2.0,
    allow_origin: Annotated[Optional[list[str]], typer.Option(
        help="another site whose pages may open the feed (scheme://host[:port]): a page embedding the "
             "dashboard, a reverse proxy; repeatable")] = None,
) -> None:
    """Watch a running co-simulation, or look through a finished run, in a browser."""
    require_extra("dashboard", "hycosim dashboard")
    from hycosim.dashboard.app import bind, serve
    from hycosim.dashboard.origin import normal_origin
    from hycosim.master.report import RunDirError

    for origin in allow_origin or []:
        if normal_origin(origin) is None:
            fail(f"--allow-origin {repr(origin)}: not an origin "
                 "(scheme://host[:port], http or https, no path)")
    path = Path(target)
    if path.is_dir():
        from hycosim.dashboard.finished import FinishedRun

        try:
            source = FinishedRun(path)
        except RunDirError as exc:
            fail(str(exc))
        closing = None
    else:
        from hycosim.dashboard.live import LiveFeed

        endpoint = checked_endpoint("endpoint", target)
        tls, password = monitor_credentials(endpoint, tls_ca, password_file)
        source = LiveFeed(endpoint, project, user=user, password=password, tls=tls, retry_s=retry)
        source.start()
        closing = source.close
    try:
        sock = bind(host, port)
    except OSError as exc:
        fail(f"--port: cannot serve the page on {host}:{port} ({exc.strerror or exc})")
    shown = f"[{host}]" if ":" in host else host
    out.print(f"dashboard: http://{shown}:{sock.getsockname()[1]}/", highlight=False)
    sys.stdout.flush()  # a launcher reads the address from a pipe
    try:
        serve(source, sock, tuple(allow_origin or ()))
    finally:
        if closing is not None:
            closing()
