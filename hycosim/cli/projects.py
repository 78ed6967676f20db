"""Reading the project a command names: a project JSON, or an SSP package or OSP system structure imported on the fly."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hycosim.cli.output import fail, warn
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


def from_ssp(package: Path, project_file: Path, side: Path | None = None, step: float | None = None,
             stop: float | None = None) -> Path:
    """Import the SSP package (or an OSP system structure: an .xml, or a folder holding
    OspSystemStructure.xml) into ``project_file`` (an SSP's FMUs in a folder beside it; a
    structure's FMUs stay where they are); exit 2 with what is wrong."""
    from hycosim.fmi.osp import OspError, import_structure, is_structure
    from hycosim.fmi.ssp import SspError, import_package

    if is_structure(package):
        if side is not None:
            fail(f"{package}: --side is for an SSP package")
        try:
            made = import_structure(package, project_file, step, stop)
        except OspError as exc:
            fail(str(exc))
        for line in made.warnings:
            warn(line)
        return project_file
    try:
        return import_package(package, project_file, side, step, stop)
    except SspError as exc:
        fail(str(exc))


def project_file(file: Path, step: float | None = None, stop: float | None = None) -> Path:
    """The project file to use for FILE: itself, or for an SSP package the project imported from
    it (into a hidden folder beside it, remade each time), with the macro step and stop time
    ``step`` and ``stop`` where the package gives none."""
    from hycosim.fmi.osp import OspError, imported_structure, is_structure
    from hycosim.fmi.ssp import SspError, imported_project

    if is_structure(file):
        try:
            written, warnings = imported_structure(file, step, stop)
        except OspError as exc:
            fail(str(exc))
        for line in warnings:
            warn(line)
        return written
    if file.suffix.lower() != ".ssp":
        if step is not None or stop is not None:
            fail(f"{file}: --step and --stop are for an SSP package; a project file says "
                 "coSimulation.stepSize and stopTime")
        return file
    try:
        return imported_project(file, step, stop)
    except SspError as exc:
        fail(str(exc))


def refuse_unfit_user_code(file: Any, loaded: LoadedProject) -> None:
    """Exit 2 naming the project's observer or master algorithm that cannot be made (the user's
    code, made as the server will make it); the algorithms are imported only for a user's."""
    from hycosim.master.observers import ObserverLoadError, project_observers

    try:
        project_observers(loaded)
    except ObserverLoadError as exc:
        fail(f"{file}: {exc}")
    if loaded.project.coSimulation.algorithm is not None:
        from hycosim.master.algorithms.choice import AlgorithmLoadError, user_algorithm

        try:
            user_algorithm(loaded)
        except AlgorithmLoadError as exc:
            fail(f"{file}: {exc}")
