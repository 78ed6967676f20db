"""Commands on a project file: validate, schema, import (SSP in), export (SSP out)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

import hycosim
from hycosim.cli.options import SspStep, SspStop, finite
from hycosim.cli.output import fail, out, warn
from hycosim.cli.projects import from_ssp, load, project_file

app = typer.Typer()


@app.command()
def validate(
    file: Path,
    models: Annotated[bool, typer.Option(help="also check that each node's model or FMU exists and takes "
                                              "the node's ports and parameters (imports the models)")] = True,
    step: SspStep = None,
    stop: SspStop = None,
) -> None:
    """Check a project JSON (or an SSP package): print OK, or every error with its JSON path and a hint."""
    loaded = load(project_file(file, step, stop))
    p = loaded.project
    if models:
        from hycosim.node.loader import NodeLoadError, check_node

        problems = []
        for i, node in enumerate(p.nodeLists):
            try:
                check_node(node, loaded.path.parent, p.coSimulation)
            except NodeLoadError as exc:
                problems.append(f"{file}: nodeLists[{i}]: {exc}")
        if problems:
            fail(f"{file}: {len(problems)} node(s) cannot be loaded", details=problems)
        _refuse_untunable(file, loaded)
        from hycosim.cli.projects import refuse_unfit_user_code

        refuse_unfit_user_code(file, loaded)
        _check_retakes(file, loaded)
    out.print(f"OK {file}: project {p.projectName!r}, {len(p.nodeLists)} nodes, {len(p.linkLists)} links, "
              f"{len(loaded.routes)} routes, {len(p.events)} events" + ("" if models else " (models not checked)"),
              highlight=False)
    if models:
        _warn_algebraic_loops(file, loaded)
        _warn_unstated_start_dependencies(file, loaded)
    if models:
        _say_what_nodes_take_part_in(loaded)
        _say_clocks(loaded)
        _say_in_process(loaded)
    bridged = [n.nodeName for n in p.nodeLists if not (n.model or n.fmu or n.replay or n.asynchronous)]
    if bridged:
        out.print(f"{len(bridged)} node(s) wait for a bridge FMU in some tool: {', '.join(bridged)} "
                  f"(build them with: hycosim fmu build {file} -o fmus)", highlight=False)


def _refuse_untunable(file: Any, loaded: Any) -> None:
    """Exit 2 naming the scenario's action that sets a parameter an FMU does not declare tunable."""
    from hycosim.node.loader import untunable

    for i, action in enumerate(loaded.project.scenario):
        if action.parameter is None:
            continue
        node, _, name = action.parameter.partition(".")
        why = untunable(loaded.project.node(node), loaded.resolve("."), name)
        if why is not None:
            fail(f"{file}: scenario[{i}].parameter: {why}")


def _say_what_nodes_take_part_in(loaded: Any) -> None:
    """A table of what each stepping node can take part in (checkpoints, iteration, localisation,
    interpolation: each needs something of its model), and a warning where the project asks
    for checkpoints or localisation that a node cannot give (the run goes without, and says so
    in meta.json). Iteration a node cannot take is refused, and interpolation warned of, by
    :func:`_check_retakes`."""
    from rich.table import Table

    from hycosim.cli.output import print_table
    from hycosim.node.loader import why_no_checkpoint, why_no_interpolation, why_no_retake

    p, folder = loaded.project, loaded.path.parent
    cosim = p.coSimulation
    nodes = p.stepping_nodes()
    if not nodes:
        return
    table = Table("node", "checkpoints", "iteration", "localisation", "interpolation",
                  title="what each stepping node can take part in")
    for n in nodes:
        checkpoint = why_no_checkpoint(n, folder)
        localise = why_no_retake(n, folder, True)
        cells = [checkpoint, why_no_retake(n, folder, False), localise,
                 why_no_interpolation(n, folder) if n.input else "it has no inputs"]
        table.add_row(n.nodeName, *("yes" if why is None else f"no: {why}" for why in cells))
        if checkpoint is not None and cosim.checkpointEvery is not None:
            warn(f"coSimulation.checkpointEvery: node {n.nodeName!r} cannot take part in checkpoints: "
                 f"{checkpoint}; the run takes none, and a lost node ends it")
        if localise is not None and cosim.eventTolerance is not None and p.events:
            warn(f"coSimulation.eventTolerance: node {n.nodeName!r} cannot take a step again with another "
                 f"length: {localise}; guards are located at macro-step points only")
    print_table(table)


def _say_clocks(loaded: Any) -> None:
    """The clocks of each FMU node that has any, as hycosim ticks them (an FMU with a clock it
    cannot tick was refused, naming it)."""
    from hycosim.node.loader import fmu_mapping

    for n in loaded.project.nodeLists:
        if n.fmu and not n.replay:
            clocks = fmu_mapping(n, loaded.path.parent).clocks
            if clocks:
                out.print(f"node {n.nodeName!r}: clock{'s' if len(clocks) > 1 else ''} "
                          f"{', '.join(c.describe() for c in clocks)}, ticked in event mode at t0 + shift + "
                          "k·interval", highlight=False)


def _say_in_process(loaded: Any) -> None:
    """Whether ``hycosim run --in-process`` can host the project, and what one process does not give."""
    from hycosim.core.config import in_process_refusals

    refused = in_process_refusals(loaded.project)
    if refused:
        out.print("in one process (--in-process): no, " + "; ".join(f"node {n!r}: {why}" for n, why in refused.items()),
                  highlight=False)
    else:
        out.print("in one process (--in-process): yes; there a node that crashes takes the run down, and no "
                  "node is started again", highlight=False)


def _check_retakes(file: Path, loaded: Any) -> None:
    """Iterative coupling and the error-controlled step need every stepping node to take a step
    again: name each one that cannot, exit 2."""
    from hycosim.node.loader import why_no_retake

    cosim = loaded.project.coSimulation
    for key, variable in (("iterate", False), ("stepControl", True)):
        if getattr(cosim, key) is None:
            continue
        unable = [(n.nodeName, why) for n in loaded.project.stepping_nodes()
                  if (why := why_no_retake(n, loaded.path.parent, variable))]
        if unable:
            fail(f"{file}: coSimulation.{key}: every stepping node must be able to take a step again"
                 f"{' with another length' if variable else ''}", details=[f"node {name!r}: {why}" for name, why in unable])
    if cosim.iterate is not None and cosim.iterate.interpolate:
        from hycosim.node.loader import why_no_interpolation

        for n in loaded.project.stepping_nodes():
            if n.input and (why := why_no_interpolation(n, loaded.path.parent)):
                warn(f"{file}: coSimulation.iterate.interpolate: node {n.nodeName!r} holds its inputs at the "
                     f"step's end value: {why}")


def _warn_unstated_start_dependencies(file: Path, loaded: Any) -> None:
    """Name each linked FMU output whose start dependencies its model structure leaves unsaid:
    the initialisation takes it as reading every input."""
    from hycosim.node.loader import fmu_mapping

    p = loaded.project
    fed = {r.dst_node for r in loaded.routes}
    for n in p.stepping_nodes():
        if n.fmu and n.nodeName in fed and p.coSimulation.initialize.enabled:
            mapping = fmu_mapping(n, loaded.path.parent)
            ports = mapping.unstated_start_dependencies()
            if ports and mapping.md.fmiVersion == "1.0":
                warn(f"{file}: node {n.nodeName!r}: its FMU is FMI 1.0, which says nothing of which inputs an "
                     "output reads: the initialisation takes every input as read")
            elif ports:
                warn(f"{file}: node {n.nodeName!r}: its FMU's model structure does not say which inputs "
                     f"{', '.join(ports)} depend{'s' if len(ports) == 1 else ''} on at the start (no dependencies in "
                     "InitialUnknowns or Outputs): the initialisation takes every input as read")


def _warn_algebraic_loops(file: Path, loaded: Any) -> None:
    """Name each cycle of direct feedthrough, which a step-by-step scheme takes a step late."""
    from hycosim.node.loader import feedthrough_of
    from hycosim.core.coupling import algebraic_loops

    p = loaded.project
    feedthrough = {n.nodeName: feedthrough_of(n, loaded.path.parent) for n in p.stepping_nodes()}
    for loop in algebraic_loops(loaded.routes, feedthrough):
        if p.coSimulation.iterate is None:
            warn(f"{file}: algebraic loop {' → '.join(loop)}: "
                 f"{p.coSimulation.coupling.replace('gauss-seidel', 'Gauss-Seidel').replace('jacobi', 'Jacobi')} "
                 "coupling takes it a macro step late; coSimulation.iterate solves it at each step")
        else:
            out.print(f"algebraic loop {' → '.join(loop)}: solved at each step by coSimulation.iterate",
                      highlight=False)


@app.command()
def schema(
    output: Annotated[Optional[Path], typer.Option("-o", "--output", help="write it here (default: stdout)")] = None,
) -> None:
    """The JSON Schema of the project file: name it in a project with "$schema" and an editor
    checks and completes the file as you type."""
    from hycosim.core.schema import project_json_schema

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
    step: Annotated[Optional[float], typer.Option(min=0.0, callback=finite,
                                                  help="the macro step, when the package gives none")] = None,
    stop: Annotated[Optional[float], typer.Option(callback=finite,
                                                  help="the stop time, when the package gives none")] = None,
) -> None:
    """Turn an SSP package or an OSP system structure into a project JSON to edit and keep.

    Components or simulators become nodes, connections links, parameter bindings or initial
    values parameters, the experiment coSimulation. An OSP structure is its
    OspSystemStructure.xml or the folder holding it."""
    from hycosim.fmi.osp import is_structure

    written = from_ssp(package, output, side=side, step=step, stop=stop)
    loaded = load(written)
    where = ("FMUs where the structure has them" if is_structure(package)
             else f"FMUs in {written.parent / (written.stem + '-fmus')}")
    out.print(f"{written}: project {loaded.project.projectName!r}, {len(loaded.project.nodeLists)} nodes, "
              f"{len(loaded.routes)} routes ({where})", highlight=False)


@app.command("export")
def export_ssp(
    file: Path,
    output: Annotated[Path, typer.Option("-o", "--output", help="the .ssp package to write")] = Path("system.ssp"),
) -> None:
    """Write a project whose nodes are all FMUs as an SSP 1.0 package (FMPy's simulate_ssp reads it)."""
    from hycosim.fmi.ssp import SspError, write_ssp

    loaded = load(file)
    try:
        written = write_ssp(loaded, output)
    except SspError as exc:
        fail(str(exc))
    out.print(f"{written}: {len(loaded.project.nodeLists)} components, {len(loaded.routes)} connections",
              highlight=False)


# The schema as shipped: package data of hycosim, named by the shipped configs.
SCHEMA_FILE = Path(hycosim.__file__).resolve().parent / "project.schema.json"
