"""Checks of command-line values that Typer's own types do not make."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Optional

import click
import typer

from hycosim.cli.output import fail
from hycosim.core.endpoints import EndpointError, parse_endpoint


def finite(value: float | None) -> float | None:
    """A float option's check where its range does not make one: nan passes a bounded range
    (every comparison with it is false), nan and inf an option without bounds, inf one with a
    lower bound alone. Every float option takes it."""
    if value is not None and not math.isfinite(value):
        raise typer.BadParameter(f"{value} is not a finite number")
    return value


# Time-triggered overrides beside the project's own scenario (a JSON list of actions).
ScenarioFile = Annotated[Optional[Path], typer.Option(
    "--scenario", help="a scenario file: overrides of inputs in time, beside the project's 'scenario'")]

# The run's tables as CSV or Parquet, in place of the project's recording.format.
RecordFormat = Annotated[Optional[str], typer.Option(
    "--record", click_type=click.Choice(["csv", "parquet"]), show_default=False,
    help="the tables as csv (values.csv, timing.csv) or parquet (values.parquet, …; the [parquet] extra); "
         "default: the project's recording.format")]

# An SSP package's macro step and stop time (SSP 1.0 has no step), for the commands that take a
# package as they take a project file; the side file's coSimulation has the last word.
SspStep = Annotated[Optional[float], typer.Option("--step", min=0.0, callback=finite,
                                                  help="an SSP package's macro step (SSP 1.0 has none)")]
SspStop = Annotated[Optional[float], typer.Option("--stop", callback=finite,
                                                  help="an SSP package's stop time, in place of its own")]


def checked_endpoint(option: str, value: str, parse=parse_endpoint) -> str:
    """An address given on the command line, normalised; exit 2 naming the option if unusable."""
    try:
        return str(parse(value))
    except EndpointError as exc:
        fail(f"{option}: {exc}")


def monitor_credentials(endpoint: str, tls_ca: Path | None, password_file: Path | None) -> tuple[dict | None, str | None]:
    """A monitor's TLS settings and password (``status``, ``dashboard``); exit 2 naming what is wrong."""
    from hycosim.transport.security import SecurityError, ca_settings, read_password

    if endpoint.startswith("tls/") and tls_ca is None:
        fail(f"{endpoint} is a TLS endpoint: give --tls-ca with the CA that signed "
             "the server's certificate")
    try:
        return ca_settings(tls_ca) if tls_ca else None, read_password(password_file) if password_file else None
    except SecurityError as exc:
        fail(str(exc))
