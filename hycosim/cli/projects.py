"""Reading the project a command names: a project JSON, or an SSP package imported on the fly."""

from __future__ import annotations

import json
from pathlib import Path

from hycosim.cli.output import fail
from hycosim.core.config import ConfigError, LoadedProject, load_project


def load(path: Path) -> LoadedProject:
    """The project file, loaded and checked; exit 2 listing every problem in it."""
    try:
        return load_project(path)
    except ConfigError as exc:
        fail(f"{exc.source}: {len(exc.issues)} error(s)", details=[f"{exc.source}: {i.render()}" for i in exc.issues])


def scenario_of(path: Path | None, loaded: LoadedProject) -> list | None:
    """The actions of ``--scenario FILE`` checked against the project; exit 2 listing every problem."""
    if path is None:
        return None
    from hycosim.core.scenario_checks import load_scenario

    try:
        return load_scenario(path, loaded.project, loaded.routes)
    except ConfigError as exc:
        fail(f"--scenario {exc.source}: {len(exc.issues)} error(s)",
             details=[f"{exc.source}: {i.render()}" for i in exc.issues])


# Beside a package, the parts of a project SSP has no word for (serverIP, events, asynchronous
# nodes, coSimulation keys): `run` and `validate` of system.ssp read system.hycosim.json.
SSP_SIDE_SUFFIX = ".hycosim.json"


def from_ssp(package: Path, project_file: Path, side: Path | None = None, step: float | None = None,
             stop: float | None = None) -> Path:
    """Import the SSP package into ``project_file`` (its FMUs in a folder beside it); exit 2 with
    what is wrong."""
    from hycosim.core import json_text
    from hycosim.fmi.ssp import SspError, project_from_ssp

    side = side or (package.with_name(package.stem + SSP_SIDE_SUFFIX) if
                    package.with_name(package.stem + SSP_SIDE_SUFFIX).is_file() else None)
    try:
        extra = json_text.loads(side.read_bytes()) if side is not None else None
        if extra is not None and type(extra) is not dict:
            raise ValueError("it holds no JSON object")
    except (OSError, ValueError) as exc:
        fail(f"{side}: cannot read the side file ({exc})")
    try:
        doc = project_from_ssp(package, project_file.parent / f"{project_file.stem}-fmus", side=extra, step=step,
                               stop=stop)
    except SspError as exc:
        fail(str(exc))
    try:
        project_file.write_text(json.dumps(doc, indent=1))
    except OSError as exc:
        fail(f"{project_file}: cannot write ({exc.strerror or exc})")
    return project_file


def project_file(file: Path, step: float | None = None, stop: float | None = None) -> Path:
    """The project file to use for FILE: itself, or for an SSP package the project imported from
    it (into a hidden folder beside it, remade each time), with the macro step and stop time
    ``step`` and ``stop`` where the package gives none."""
    if file.suffix.lower() != ".ssp":
        if step is not None or stop is not None:
            fail(f"{file}: --step and --stop are for an SSP package; a project file says "
                 "coSimulation.stepSize and stopTime")
        return file
    folder = file.parent / f".{file.name}.d"
    try:
        folder.mkdir(exist_ok=True)
    except OSError as exc:
        fail(f"{folder}: cannot make the folder the package is imported into "
             f"({exc.strerror or exc}); import it elsewhere with: hycosim import {file} -o DIR/project.json")
    return from_ssp(file, folder / "project.json", step=step, stop=stop)
