"""The example projects that ship with hycosim, and writing one into a folder of the user's.

A shipped project lies inside the installed package, where a user should neither look for it
nor build into it. :func:`write_example` copies one out with what it needs beside it: the
project file's JSON Schema, and the FMUs that get built (the grasp demo's scene FMUs) in a
``fmus/`` folder, its nodes pointed at them. The framework's own examples are listed here;
other packages (the grasp demo) add theirs as entry points of ``hycosim.examples``.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from hycosim.core.folders import make_folder

EXAMPLE_GROUP = "hycosim.examples"
PACKAGE = Path(__file__).resolve().parent.parent
SCHEMA = PACKAGE / "project.schema.json"
FMU_FOLDER = "fmus"


class ExampleError(RuntimeError):
    """An example that is not there, or cannot be written where asked."""


@dataclass(frozen=True)
class Example:
    """One shipped project: its name, a line saying what it shows, its file, the extra its
    nodes need to run (None: the core), and what builds the FMUs it names (a function of
    the folder they go into), if any."""

    name: str
    summary: str
    project: Path
    extra: str | None = None
    build_fmus: Callable[[Path], object] | None = None


DEFAULT = Example("default", "a pendulum caught by a moving hand (an event), a gain chain, a 30 Hz sensor: "
                  "the reference models only", PACKAGE / "configs" / "default.json")


def examples() -> dict[str, Example]:
    """Every example, by name: the framework's and those installed packages register."""
    from importlib.metadata import entry_points

    found = {DEFAULT.name: DEFAULT}
    for ep in entry_points(group=EXAMPLE_GROUP):
        try:
            example = ep.load()
        except Exception:  # a package whose extra is missing or that is damaged: its examples are not listed
            continue
        if isinstance(example, Example):
            found.setdefault(example.name, example)
    return found


def write_example(example: Example, folder: Path) -> Path:
    """Write ``example`` into ``folder`` (made if missing): ``NAME.json``, the schema it names,
    and the FMUs it needs built into ``folder/fmus``. Returns the project file's path."""
    try:
        project = json.loads(example.project.read_text())
    except (OSError, ValueError) as exc:
        raise ExampleError(f"example {example.name!r}: its project {example.project} cannot be read "
                           f"({exc}); reinstall hycosim") from None
    make_folder(folder)
    if SCHEMA.is_file():
        shutil.copyfile(SCHEMA, folder / SCHEMA.name)
        project["$schema"] = SCHEMA.name
    else:
        project.pop("$schema", None)
    for node in project.get("nodeLists", []):
        if isinstance(node, dict) and isinstance(node.get("fmu"), str):
            node["fmu"] = f"{FMU_FOLDER}/{Path(node['fmu']).name}"
    if example.build_fmus is not None:
        example.build_fmus(folder / FMU_FOLDER)
    path = folder / f"{example.name}.json"
    path.write_text(json.dumps(project, indent=1) + "\n")
    return path
