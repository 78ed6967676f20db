"""``hycosim fmu``: build bridge FMUs from a project; inspect an FMU."""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Annotated, Optional

import typer
from rich.table import Table

from hycosim.cli.options import checked_endpoint
from hycosim.cli.output import fail, out, print_table
from hycosim.cli.projects import load
from hycosim.core.endpoints import GATEWAY_PORT, parse_address

app = typer.Typer(no_args_is_help=True, help="Build bridge FMUs from a project; inspect FMUs.")


@app.command("build")
def fmu_build(
    file: Path,
    output: Annotated[Path, typer.Option("-o", "--output", help="folder for the .fmu files")] = Path("fmus"),
    node: Annotated[Optional[list[str]], typer.Option(help="only these nodes (repeatable)")] = None,
    server: Annotated[Optional[str], typer.Option(help="gateway HOST:PORT baked in as the default")] = None,
) -> None:
    """Write one native FMI 2.0 co-simulation bridge FMU per stepping node of the project."""
    from fmpy.validation import validate_fmu

    from hycosim.bridge.bridge_fmu import BridgeBuildError, build_bridge_fmus

    loaded = load(file)
    if not output.is_dir() and not output.parent.is_dir():
        # One folder is made for the FMUs; a tree of them is more likely a mistyped path.
        fail(f"-o {output}: its parent folder {output.parent} does not exist")
    if server is not None:
        server = checked_endpoint("--server", server, partial(parse_address, default_port=GATEWAY_PORT))
    unknown = [n for n in node or [] if n not in {x.nodeName for x in loaded.project.nodeLists}]
    if unknown:
        fail(f"{file}: no node named {', '.join(unknown)}")
    try:
        built = build_bridge_fmus(loaded, output, server, node)
    except BridgeBuildError as exc:
        fail(f"{file}: {exc}")
    for b in built:
        problems = validate_fmu(str(b.path))
        status = "valid" if not problems else "INVALID: " + "; ".join(problems)
        out.print(f"{b.path}  ({b.model_identifier}, {status})", highlight=False)
        if problems:
            raise typer.Exit(4)


@app.command("inspect")
def fmu_inspect(
    fmu: Path,
    config: Annotated[Optional[Path], typer.Option(help="a project JSON: show how a node's ports map")] = None,
    node: Annotated[Optional[str], typer.Option(help="the node of --config (default: the one naming this FMU)")] = None,
) -> None:
    """List an FMU's co-simulation capabilities and variables; with --config, the port mapping."""
    import fmpy

    from hycosim.fmi.loader import (CO_SIMULATION, MODEL_EXCHANGE, FmuError, check_platform,
                                               clock_refusal, clocks_of, describe, map_driven, map_ports, shape_of)

    try:
        md = describe(fmu)
    except FmuError as exc:
        fail(str(exc))
    cs, me = md.coSimulation, md.modelExchange
    caps = Table(title=f"{fmu.name}: FMI {md.fmiVersion}, {md.modelName}")
    caps.add_column("capability")
    caps.add_column("value")
    se = getattr(md, "scheduledExecution", None)
    caps.add_row("interfaces", ", ".join(["co-simulation"] * bool(cs) + ["Model Exchange (the node integrates it)"] * bool(me)
                                         + ["scheduled execution (hycosim does not run it)"] * bool(se)) or "none")
    caps.add_row("platforms", ", ".join(fmpy.supported_platforms(str(fmu))) or "-")
    for label, element, attrs in (
            ("co-simulation", cs, ("canGetAndSetFMUstate", "canSerializeFMUstate", "canHandleVariableCommunicationStepSize",
                                   "needsExecutionTool", "hasEventMode", "canReturnEarlyAfterIntermediateUpdate")),
            ("Model Exchange", me, ("canGetAndSetFMUstate", "canSerializeFMUstate", "needsCompletedIntegratorStep"))):
        if element is None:
            continue
        caps.add_row(f"{label}: modelIdentifier", element.modelIdentifier)
        for attr in attrs:
            if hasattr(element, attr):
                caps.add_row(f"{label}: {attr}", str(bool(getattr(element, attr))))
    if md.fmiVersion == "1.0":
        caps.add_row("FMI 1.0", "runs as a node (co-simulation, or Model Exchange integrated by the node), "
                     "initialised whole in its setup (FMI 1.0 has no initialisation mode); no state to get or "
                     "set: no checkpoints, retakes, iteration or event localisation")
    if me is not None:
        caps.add_row("continuous states, event indicators",
                     f"{md.numberOfContinuousStates or 0}, {md.numberOfEventIndicators or 0}")
    print_table(caps)
    variables = Table(title="variables")
    for col in ("name", "causality", "variability", "type", "shape", "start", "unit"):
        variables.add_column(col)
    for v in md.modelVariables:
        try:
            shape = shape_of(md, v, {}, fmu)
        except FmuError as exc:
            shape = f"invalid: {exc}"
        variables.add_row(v.name, v.causality or "", v.variability or "", v.type, str(list(shape)) if shape else "",
                          "" if v.start is None else str(v.start), getattr(v, "unit", None) or "")
    print_table(variables)
    clocks = clocks_of(md, fmu)
    if clocks:
        table = Table(title="clocks")
        for col in ("name", "causality", "kind", "interval (s)", "shift (s)", "ticked by hycosim"):
            table.add_column(col)
        for c in clocks:
            table.add_row(c.name, c.causality, c.kind, "" if c.interval is None else f"{c.interval:g}",
                          f"{c.shift:g}" if c.interval is not None else "", "no: " + c.refusal() if c.refusal() else "yes")
        print_table(table)
        why = clock_refusal(md, fmu, CO_SIMULATION if cs is not None else MODEL_EXCHANGE)
        out.print("clocks: " + (f"refused: {why}" if why else "hycosim runs this FMU, ticking each clock at "
                            "t0 + shift + k·interval in event mode"))
    if config is None:
        return
    loaded = load(config)
    spec = None
    if node:
        try:
            spec = loaded.project.node(node)
        except KeyError:
            fail(f"{config}: no node named {node!r}")
    else:
        spec = next((n for n in loaded.project.nodeLists if n.fmu and loaded.resolve(n.fmu) == fmu.resolve()), None)
        if spec is None:
            fail(f"{config}: no node names {fmu}; pick one with --node")
    try:
        check_platform(fmu, md, spec.nodeName)
        inputs, outputs = map_ports(md, spec, fmu)
        driven = map_driven(md, spec, fmu)
    except FmuError as exc:
        fail(str(exc))
    mapping = Table(title=f"node {spec.nodeName!r} → {fmu.name}")
    for col in ("port", "direction", "FMU variable", "value reference", "type"):  # every port is a scalar
        mapping.add_column(col)
    for direction, ports in (("input", inputs), ("output", outputs)):
        for m in ports:
            mapping.add_row(m.port, direction, m.variable, str(m.vr), m.type)
    if driven is not None:
        mapping.add_row("(driven flag)", "input", driven.name, str(driven.valueReference), driven.type)
    print_table(mapping)
