"""What the command line shows: its consoles, errors, tables, a process's last word.

Exit codes: 0 success, 2 bad input (config, arguments, run directory, a missing extra), 3 a run
that failed (timeout, lost node, server gone), 4 an internal error or an invalid FMU built,
5 a node whose run the server stopped because it failed elsewhere (the server says why),
130 Ctrl-C.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from typing import NoReturn

import typer
from rich.console import Console
from rich.table import Table
from rich.text import Text

out = Console(soft_wrap=True)
err = Console(stderr=True, soft_wrap=True)


def say_error(message: str, details: Iterable[str] = ()) -> None:
    """Say what went wrong on stderr: ``error: message``, then each detail on a line of its own.
    The text is shown as it is: a file name or a value the user gave may hold brackets, which
    rich would take for markup."""
    err.print(Text.assemble(("error:", "red"), " ", message), highlight=False)
    for line in details:
        err.print(Text(f"  {line}"), highlight=False)


def fail(message: str, code: int = 2, details: Iterable[str] = ()) -> NoReturn:
    """Say what went wrong (:func:`say_error`) and end the command with ``code``."""
    say_error(message, details)
    raise typer.Exit(code)


def warn(message: str) -> None:
    """A warning on stderr: the command goes on."""
    err.print(Text.assemble(("warning:", "yellow"), " ", message), highlight=False)


def print_table(table: Table) -> None:
    """A table on stdout, whole: on a pipe or in a file rich would cut cells to 80 columns
    (``Float64_fixed_pa…``), and a name cut short is a wrong name."""
    (out if out.is_terminal else Console(width=100_000)).print(table)


def end_process(code: int) -> NoReturn:
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


def say_outcome(console: Console, text: str, error: bool = False) -> None:
    """Print a process's last word, as it is (a message may quote brackets, which rich would
    take for markup), after ``error:`` where it is one. Its stderr may be a file on a disk that
    just filled up (a launched node's): the exit status still tells the outcome, so a failed
    print is let go."""
    try:
        console.print(Text.assemble(("error:", "red"), " ", text) if error else Text(text), highlight=False)
    except OSError:
        pass


def print_summary(s) -> None:
    """Print a run's :class:`~hycosim.master.report.RunSummary` as the command line's closing lines:
    status, steps, rate, mode switches, where the results are, and who ended the run where a node
    did."""
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
