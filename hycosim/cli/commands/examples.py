"""``hycosim examples``: the shipped example projects, listed or written into a folder."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from hycosim.cli.output import fail, out
from hycosim.core.examples import ExampleError, examples as shipped, write_example
from hycosim.core.extras import install_hint, missing_modules
from hycosim.core.hints import did_you_mean

app = typer.Typer()


@app.command("examples")
def examples_command(
    name: Annotated[Optional[str], typer.Argument(help="the example to write (none: list them)",
                                                  metavar="NAME")] = None,
    output: Annotated[Optional[Path], typer.Option("-o", "--output", help="folder to write it into")] = None,
) -> None:
    """List the example projects, or write one with what it needs into a folder (-o DIR)."""
    found = shipped()
    if name is None:
        if output is not None:
            fail("-o names where an example goes: give its NAME too (hycosim examples lists them)")
        for example in found.values():
            needs = f"  [{example.extra}]" if example.extra else ""
            out.print(f"{example.name:<14}{example.summary}{needs}", highlight=False, markup=False)
        return
    if name not in found:
        fail(f"no example named {name!r}{did_you_mean([name], found)}; hycosim examples lists them")
    example = found[name]
    missing = missing_modules(example.extra) if example.extra else []
    if missing and example.build_fmus is not None:
        fail(f"example {name!r} builds FMUs, which needs hycosim's [{example.extra}] extra "
             f"({', '.join(missing)} not installed): {install_hint(example.extra)}")
    if output is None:
        fail(f"give the folder to write example {name!r} into: hycosim examples {name} -o DIR")
    try:
        path = write_example(example, output)
    except ExampleError as exc:
        fail(str(exc))
    out.print(f"wrote {path}", highlight=False)
    if missing:
        out.print(f"running it needs hycosim's [{example.extra}] extra ({', '.join(missing)} not installed): "
                  f"{install_hint(example.extra)}", highlight=False, markup=False)
    out.print(f"next: hycosim validate {path}   then: hycosim run {path}", highlight=False)
