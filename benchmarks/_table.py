"""A benchmark's current figures as the manual shows them.

Every script that ``make bench`` runs takes ``--table FILE`` and writes there, as Markdown,
what it measured: a line naming the command, the date and the machine, then its table(s).
``make bench`` writes them to ``benchmarks/results/NAME.md``, and the manual's build includes
each where a page says ``<!-- bench: NAME -->`` (``docs/hooks.py``): the figures in the manual
are those of the last ``make bench``, never typed by hand.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass
class Table:
    """One Markdown table: a caption above it, a header, rows, and a remark below it."""

    caption: str
    header: list[str]
    rows: list[list[Any]] = field(default_factory=list)
    after: str = ""

    def markdown(self) -> list[str]:
        """The table as the manual's Markdown lines: caption, header, rows (a missing cell as a dash),
        and the text after it."""
        lines = [self.caption, "", "| " + " | ".join(self.header) + " |", "|" + "---|" * len(self.header)]
        lines += ["| " + " | ".join("–" if c is None else str(c) for c in row) + " |" for row in self.rows]
        return lines + (["", self.after] if self.after else [])


def add_argument(ap: argparse.ArgumentParser) -> None:
    """The ``--table FILE`` option of every benchmark ``make bench`` runs."""
    ap.add_argument("--table", type=Path, metavar="FILE",
                    help="also write the figures as the manual's Markdown table here "
                         "(make bench: benchmarks/results/NAME.md)")


def command() -> str:
    """The command line that measured the figures, without the options that only say where
    they go."""
    args, skip = [], False
    for arg in sys.argv[1:]:
        if skip:
            skip = False
        elif arg == "--table":
            skip = True
        elif arg != "--json" and not arg.startswith("--table="):
            args.append(arg)
    return " ".join([Path(sys.argv[0]).name, *args])


def _processor() -> str:
    """The machine and, where Linux says it, the processor's model: ratios between systems moved
    by a fifth from one 2-core machine to another (benchmarks/FINDINGS.md, 2026-12-04, fifth entry)."""
    try:
        with open("/proc/cpuinfo") as info:
            model = next((line.split(":", 1)[1].strip() for line in info if line.startswith("model name")), "")
    except OSError:
        model = ""
    return f"{platform.machine()}, {model}" if model else platform.machine()


def write(path: Path | None, *tables: Table) -> None:
    """Write ``tables`` to ``path`` (nothing when None) under one line saying how, when and where
    they were measured."""
    if path is None:
        return
    lines = [f"`{command()}`, {time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores ({_processor()}):", ""]
    for i, table in enumerate(tables):
        lines += ([""] if i else []) + table.markdown()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def rate(value: float | None) -> str | None:
    """Steps per second as the manual writes them: 2,658."""
    return None if value is None else f"{value:,.0f}"


def ratio(a: float | None, b: float | None, digits: int = 2) -> str | None:
    """a / b to ``digits`` places, or None where either is missing."""
    return None if not a or not b else f"{a / b:.{digits}f}"
