"""Loading a project file: the JSON read, its shape checked against the schema
(:mod:`hycosim.core.schema`), then what spans entries (links against ports, modes, guards, the
coupling) checked by :func:`check_semantics`. Both passes report every error with its JSON
path, so one run of ``hycosim validate`` lists all that is wrong.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, NamedTuple

from pydantic import ValidationError

from hycosim.core.coupling import CouplingPlan, coupling_issues, plan
from hycosim.core.scenario_checks import scenario_issues
from hycosim.core.endpoints import GATEWAY_PORT, SERVER_PORT, Address, EndpointError, gateway_beside, parse_address, parse_endpoint
from hycosim.core.guards import Guard, GuardError
from hycosim.core.schema import ASSIGNABLE, FREE_MODE, Issue, PortType, Project, Route


class ConfigError(Exception):
    """A project file that cannot be used, with every problem found in it."""

    def __init__(self, source: str, issues: list[Issue]):
        self.source = source
        self.issues = issues
        lines = "\n".join(f"  {source}: {i.render()}" for i in issues)
        super().__init__(f"{source}: {len(issues)} error(s) in project file\n{lines}")


class EventGuards(NamedTuple):
    """An event's compiled guards; ``rearm`` is None for the default (``when`` stopped holding)."""

    when: Guard
    until: Guard
    rearm: Guard | None = None


@dataclass
class LoadedProject:
    """A validated project with its resolved routes and compiled guards."""

    project: Project
    path: Path | None
    routes: list[Route]
    guards: dict[str, EventGuards] = field(default_factory=dict)
    digest: str = ""

    @property
    def name(self) -> str:
        """The project's name (``projectName``), which keys its Zenoh traffic and its run folders."""
        return self.project.projectName

    @cached_property
    def coupling(self) -> CouplingPlan:
        """How the stepping nodes are coupled: their rates and, for Gauss-Seidel, their order."""
        return plan(self.project, self.routes)

    def resolve(self, relative: str) -> Path:
        """Resolve a path written in the project file against the file's folder."""
        base = self.path.parent if self.path else Path.cwd()
        return (base / relative).resolve()


def _reject_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    seen: dict[str, Any] = {}
    for key, value in pairs:
        if key in seen:
            raise ValueError(f"duplicate key {key!r}")
        seen[key] = value
    return seen


def pydantic_issues(err: ValidationError, prefix: str = "") -> list[Issue]:
    """Pydantic's errors as issues with a JSON path each (below ``prefix``) and a hint."""
    issues = []
    for e in err.errors():
        path = prefix
        for part in e["loc"]:
            path += f"[{part}]" if isinstance(part, int) else (f".{part}" if path else str(part))
        msg = e["msg"]
        hint = ""
        if e["type"] == "extra_forbidden":
            msg = "unknown key"
            hint = "check the spelling; keys are case-sensitive camelCase as in docs/project-file.md"
        elif e["type"] == "missing":
            hint = "this key is required"
        issues.append(Issue(path or "(top level)", msg, hint))
    return issues


def _split_port_ref(ref: str) -> tuple[str, str] | None:
    if ref.count(".") != 1:
        return None
    node, port = ref.split(".")
    return (node, port) if node and port else None


_ELEMENT = re.compile(r"^(?P<port>[^\[\]]+)\[(?P<index>\d{1,9})\]$")


def _split_element(port: str) -> tuple[str, int | None]:
    """``"y[2]"`` → ``("y", 2)``: one element of an array port; ``"y"`` → ``("y", None)``."""
    m = _ELEMENT.match(port)
    return (m["port"], int(m["index"])) if m else (port, None)


def _shape_text(shape: tuple[int, ...] | None) -> str:
    return "a scalar" if shape is None else f"an array of shape {list(shape)}"


def _resolve_routes(project: Project, issues: list[Issue]) -> list[Route]:
    nodes = {n.nodeName: n for n in project.nodeLists}
    modes = set(project.modes())
    routes: list[Route] = []
    for i, link in enumerate(project.linkLists):
        where = f"linkLists[{i}]"
        if link.activeIn is not None:
            for mode in link.activeIn:
                if mode not in modes:
                    issues.append(Issue(f"{where}.activeIn", f"unknown mode {mode!r}",
                                        f"modes are {sorted(modes)}"))
        active = frozenset(link.activeIn) if link.activeIn is not None else None
        if link.pairs is None:
            src = _split_port_ref(link.source)
            dst = _split_port_ref(link.target)
            if src is None or dst is None:
                key, ref = ("from", link.source) if src is None else ("to", link.target)
                issues.append(Issue(f"{where}.{key}", f"{ref!r} is not 'node.port'",
                                    "write 'node.port', or name nodes and give 'pairs'"))
                continue
            pairs = [(src[0], src[1], dst[0], dst[1])]
        else:
            # A link's nodes are named once for all its pairs: an unknown one is said once.
            unknown = [(key, name) for key, name in (("from", link.source), ("to", link.target)) if name not in nodes]
            for key, name in unknown:
                issues.append(Issue(f"{where}.{key}", f"unknown node {name!r}", f"nodes are {sorted(nodes)}"))
            if unknown:
                continue
            pairs = [(link.source, o, link.target, n) for o, n in link.pairs]
        for j, (sn, sp, dn, dp) in enumerate(pairs):
            pw = where if link.pairs is None else f"{where}.pairs[{j}]"
            sp, element = _split_element(sp)
            ok = True
            if _split_element(dp)[1] is not None:
                issues.append(Issue(f"{pw}.to", f"{dn}.{dp} names one element of an input",
                                    "a link feeds a whole input: make the input a scalar port, or link a whole array"))
                continue
            if sn not in nodes:
                issues.append(Issue(f"{where}.from", f"unknown node {sn!r}", f"nodes are {sorted(nodes)}"))
                ok = False
            elif sp not in nodes[sn].output_names():
                issues.append(Issue(f"{pw}.from", f"{sn}.{sp} is not an output of node {sn!r}",
                                    f"outputs of {sn} are {nodes[sn].output_names()}"))
                ok = False
            if dn not in nodes:
                issues.append(Issue(f"{where}.to", f"unknown node {dn!r}", f"nodes are {sorted(nodes)}"))
                ok = False
            elif dp not in nodes[dn].input_names():
                issues.append(Issue(f"{pw}.to", f"{dn}.{dp} is not an input of node {dn!r}",
                                    f"inputs of {dn} are {nodes[dn].input_names()}"))
                ok = False
            if not ok:
                continue
            src_port, dst_port = nodes[sn].port(sp), nodes[dn].port(dp)
            src_shape = src_port.shape
            if element is not None:
                if src_port.shape is None:
                    issues.append(Issue(f"{pw}.from", f"{sn}.{sp}[{element}] indexes a scalar port",
                                        f"{sn}.{sp} is no array; link it as {sn}.{sp}"))
                    continue
                if element >= src_port.size:
                    issues.append(Issue(f"{pw}.from", f"{sn}.{sp}[{element}] is out of range",
                                        f"{sn}.{sp} has shape {list(src_port.shape)}: elements 0 to "
                                        f"{src_port.size - 1}, row-major"))
                    continue
                src_shape = None
            if src_shape != dst_port.shape:
                shown = f"{sn}.{sp}" + ("" if element is None else f"[{element}]")
                issues.append(Issue(pw, f"shape mismatch: {shown} is {_shape_text(src_shape)}, {dn}.{dp} is "
                                    f"{_shape_text(dst_port.shape)}",
                                    "link arrays of the same shape, or one element (node.port[i]) to a scalar"))
                continue
            st, dt = src_port.type, dst_port.type
            if st not in ASSIGNABLE[dt]:
                issues.append(Issue(pw, f"type mismatch: {sn}.{sp} is {st.value}, {dn}.{dp} is {dt.value}",
                                    "a link may widen (Integer→Real) but not narrow"))
                continue
            if link.extrapolation == "linear" and st is not PortType.REAL:
                issues.append(Issue(f"{where}.extrapolation", f"linear extrapolation of {st.value} port {sn}.{sp}",
                                    "use 'hold' for non-Real ports"))
            transform = None
            if link.factor is not None or link.offset is not None:
                transform = (1.0 if link.factor is None else link.factor, 0.0 if link.offset is None else link.offset)
                if dt is not PortType.REAL:
                    issues.append(Issue(f"{where}.factor" if link.factor is not None else f"{where}.offset",
                                        f"a linear transformation into {dt.value} input {dn}.{dp}",
                                        "factor and offset apply to links into Real inputs"))
            routes.append(Route(i, sn, sp, dn, dp, active, link.extrapolation, transform, element))
    # One writer per input per mode: two active feeders would make the value depend on order.
    for mode in sorted(modes):
        feeders: dict[tuple[str, str], int] = {}
        for r in routes:
            if not r.active(mode):
                continue
            key = (r.dst_node, r.dst_port)
            if key in feeders and feeders[key] != r.link_index:
                issues.append(Issue(f"linkLists[{r.link_index}].to",
                                    f"input {key[0]}.{key[1]} is also fed by linkLists[{feeders[key]}] in mode {mode!r}",
                                    "give the links disjoint 'activeIn' modes"))
            feeders.setdefault(key, r.link_index)
    return routes


def _address_issues(project: Project) -> list[Issue]:
    hint = "e.g. 127.0.0.1:7447, tcp/10.0.0.5:7447, or tls/HOST:PORT with security.tls"
    try:
        server = parse_endpoint(project.serverIP, SERVER_PORT)
    except EndpointError as exc:
        return [Issue("serverIP", str(exc), hint)]
    try:
        if project.gatewayIP is not None:
            parse_address(project.gatewayIP, GATEWAY_PORT)
        else:
            gateway_beside(server)
    except EndpointError as exc:
        return [Issue("gatewayIP", str(exc), "HOST:PORT of the TCP gateway for bridge FMUs")]
    return []


def _security_issues(project: Project) -> list[Issue]:
    sec = project.security
    tls_endpoint = project.serverIP.startswith("tls/")
    issues = []
    if sec is not None and sec.credentials is None and sec.tls is None:
        issues.append(Issue("security", "security names neither 'credentials' nor 'tls'", "give one or both"))
    if tls_endpoint and (sec is None or sec.tls is None):
        issues.append(Issue("serverIP", f"{project.serverIP} is a TLS endpoint but the project has no security.tls",
                            "add security.tls with rootCa, certificate and privateKey (PEM files)"))
    if sec is not None and sec.tls is not None:
        if not tls_endpoint:
            issues.append(Issue("security.tls", f"TLS is configured but serverIP {project.serverIP} is not a "
                                                "tls/ endpoint", "write serverIP as tls/HOST:PORT"))
        if (sec.tls.certificate is None) != (sec.tls.privateKey is None):
            issues.append(Issue("security.tls", "certificate and privateKey go together",
                                "give both (the server's), or neither in a copy for nodes only"))
    return issues


def check_semantics(project: Project) -> tuple[list[Route], dict[str, EventGuards], list[Issue]]:
    """Check everything that spans entries; return routes, compiled guards and issues."""
    issues: list[Issue] = []
    if project.nodeNum != len(project.nodeLists):
        issues.append(Issue("nodeNum", f"nodeNum is {project.nodeNum} but nodeLists has {len(project.nodeLists)} entries",
                            "make nodeNum equal the number of nodes"))
    if project.linkNum != len(project.linkLists):
        issues.append(Issue("linkNum", f"linkNum is {project.linkNum} but linkLists has {len(project.linkLists)} entries",
                            "make linkNum equal the number of links"))
    if project.coSimulation.transport == "inprocess":
        for name, why in in_process_refusals(project).items():
            issues.append(Issue("coSimulation.transport", f"an in-process run cannot host node {name!r}: {why}",
                                'run it in processes: "transport": "zenoh"'))
    names: dict[str, int] = {}
    uids: dict[int, int] = {}
    for i, n in enumerate(project.nodeLists):
        if n.nodeName in names:
            issues.append(Issue(f"nodeLists[{i}].nodeName", f"duplicate node name {n.nodeName!r}",
                                f"also used by nodeLists[{names[n.nodeName]}]"))
        names.setdefault(n.nodeName, i)
        if n.UID in uids:
            issues.append(Issue(f"nodeLists[{i}].UID", f"duplicate UID {n.UID}", f"also used by nodeLists[{uids[n.UID]}]"))
        uids.setdefault(n.UID, i)
        seen_ports: set[str] = set()
        for kind, ports in (("input", n.input), ("output", n.output)):
            for j, p in enumerate(ports):
                if p.name in seen_ports:
                    issues.append(Issue(f"nodeLists[{i}].{kind}[{j}]", f"duplicate port {n.nodeName}.{p.name}",
                                        "port names are unique within a node, inputs and outputs together"))
                seen_ports.add(p.name)
        if n.model and n.fmu:
            issues.append(Issue(f"nodeLists[{i}]", f"node {n.nodeName!r} names both 'model' and 'fmu'", "keep one"))
        solver_keys = [k for k in ("solver", "relativeTolerance", "maxStep") if getattr(n, k) is not None]
        if (n.interface or solver_keys) and not n.fmu:
            issues.append(Issue(f"nodeLists[{i}]", f"node {n.nodeName!r} names "
                                f"{', '.join(['interface'] * bool(n.interface) + solver_keys)} but no 'fmu'",
                                "they choose how an FMU node runs"))
        elif solver_keys and n.interface == "CoSimulation":
            issues.append(Issue(f"nodeLists[{i}].interface", f"node {n.nodeName!r} runs its FMU as co-simulation, "
                                f"which integrates itself: {', '.join(solver_keys)} would do nothing",
                                'set "interface": "ModelExchange", or leave them out'))
        if n.drivenVariable is not None and not n.fmu:
            issues.append(Issue(f"nodeLists[{i}].drivenVariable", f"node {n.nodeName!r} is not an FMU node",
                                "a Python node is told it is driven through set_mode; a bridge FMU through "
                                "its hycosim_driven output"))
        arrays = [p.name for p in (*n.input, *n.output) if p.shape is not None]
        if arrays and not (n.fmu or n.model or n.replay or n.asynchronous):
            issues.append(Issue(f"nodeLists[{i}]", f"node {n.nodeName!r} has array port {arrays[0]!r}, and its "
                                "bridge FMU (a node with no fmu, model or replay) carries scalars only",
                                "give the bridge node scalar ports"))
        if n.asynchronous and arrays:
            issues.append(Issue(f"nodeLists[{i}].output", f"asynchronous node {n.nodeName!r} has array port "
                                f"{arrays[0]!r}", "an asynchronous source publishes scalar samples"))
        if n.asynchronous and n.input:
            issues.append(Issue(f"nodeLists[{i}].input", f"asynchronous node {n.nodeName!r} has inputs",
                                "an asynchronous source only publishes samples"))
    issues.extend(_address_issues(project))
    issues.extend(_security_issues(project))
    cosim = project.coSimulation
    if cosim.stopTime <= cosim.startTime:
        issues.append(Issue("coSimulation.stopTime", "stopTime must be after startTime"))
    else:
        # Macro-step points are startTime + j·stepSize: below the float resolution of the
        # times involved, a step would not advance the clock and the run would never end.
        stuck = [name for name, at in (("startTime", cosim.startTime), ("stopTime", cosim.stopTime))
                 if at + cosim.stepSize == at]
        if stuck:
            issues.append(Issue("coSimulation.stepSize", f"stepSize {cosim.stepSize:g} does not advance a time "
                                f"of {getattr(cosim, stuck[0]):g} s ({stuck[0]}): the run would never end",
                                "a step above the float resolution of startTime and stopTime (about 1e-16 of them)"))
    if cosim.eventTolerance is not None and cosim.eventTolerance >= cosim.stepSize:
        # Without rollback a crossing is already placed within one step; a tolerance that is
        # no finer would make rollback bisect nothing and cost a state save every step.
        issues.append(Issue("coSimulation.eventTolerance", f"eventTolerance {cosim.eventTolerance:g} s is not "
                            f"smaller than stepSize {cosim.stepSize:g} s, so it would locate nothing",
                            "a tolerance below stepSize, or leave eventTolerance out (crossings are then "
                            "located to within one step)"))
    if not isinstance(cosim.realTime, bool) and cosim.realTime < 0:
        issues.append(Issue("coSimulation.realTime", f"realTime {cosim.realTime:g} is negative",
                            "false (as fast as possible), true, or a factor > 0 (wall time = simulated time × factor)"))
    event_names: set[str] = set()
    guards: dict[str, EventGuards] = {}
    outputs = {(n.nodeName, p.name) for n in project.nodeLists for p in n.output}
    arrays_out = {(n.nodeName, p.name) for n in project.nodeLists for p in n.output if p.shape is not None}
    for i, e in enumerate(project.events):
        if e.name == FREE_MODE or e.name in event_names:
            issues.append(Issue(f"events[{i}].name", f"event name {e.name!r} is reserved or repeated"))
        event_names.add(e.name)
        if e.drives not in names:
            issues.append(Issue(f"events[{i}].drives", f"unknown node {e.drives!r}", f"nodes are {sorted(names)}"))
        given = {key: getattr(e, key) for key in ("when", "until", "rearm") if getattr(e, key) is not None}
        compiled: dict[str, Guard] = {}
        for key, text in given.items():
            try:
                g = Guard(text)
            except GuardError as exc:
                # A node name may hold '-', which a guard reads as a minus (it reads Python names).
                dashed = sorted(n for n in names if "-" in n and f"{n}." in text)
                issues.append(Issue(f"events[{i}].{key}", str(exc),
                                    f"a guard cannot name node {dashed[0]!r}: '-' is a minus there; give the node "
                                    "a name without '-'" if dashed else "e.g. 'robot.grasped > 0.5'"))
                continue
            for ref in g.references:
                if ref not in outputs:
                    issues.append(Issue(f"events[{i}].{key}", f"guard names {ref[0]}.{ref[1]}, which is not a node output",
                                        "guards read node outputs as node.port"))
                elif ref in arrays_out:
                    issues.append(Issue(f"events[{i}].{key}", f"guard names {ref[0]}.{ref[1]}, an array port",
                                        "guards read scalar outputs; give the node a scalar output for the guard"))
            compiled[key] = g
        if len(compiled) == len(given):
            guards[e.name] = EventGuards(**compiled)
    routes = _resolve_routes(project, issues)
    issues += scenario_issues(project, routes, project.scenario)
    issues.extend(coupling_issues(project, routes))
    return routes, guards, issues


def parse_project(data: Any, source: str = "<config>", path: Path | None = None, raw: bytes = b"") -> LoadedProject:
    """Validate an already-decoded project document; raise ConfigError listing every problem."""
    try:
        project = Project.model_validate(data)
    except ValidationError as err:
        raise ConfigError(source, pydantic_issues(err)) from None
    routes, guards, issues = check_semantics(project)
    if issues:
        raise ConfigError(source, issues)
    digest = hashlib.sha256(raw or json.dumps(data, sort_keys=True).encode()).hexdigest()
    return LoadedProject(project, path, routes, guards, digest)


def load_project(path: str | Path) -> LoadedProject:
    """Read and validate a project JSON file; raise ConfigError naming the file on any problem."""
    path = Path(path)
    source = str(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ConfigError(source, [Issue("(file)", f"cannot read: {exc.strerror or exc}")]) from None
    try:
        data = json.loads(raw, object_pairs_hook=_reject_duplicate_keys)
    except json.JSONDecodeError as exc:
        raise ConfigError(source, [Issue(f"line {exc.lineno} column {exc.colno}", f"invalid JSON: {exc.msg}")]) from None
    except UnicodeDecodeError as exc:
        raise ConfigError(source, [Issue("(file)", f"not text: byte {exc.start} cannot be read as {exc.encoding}",
                                         "save the project file as UTF-8 JSON")]) from None
    except RecursionError:
        # Python's decoder recurses per level of nesting; no project file comes near that.
        raise ConfigError(source, [Issue("(top level)", "invalid JSON: nested too deeply to read",
                                         "a project file nests a few levels (nodeLists, ports, events)")]) from None
    except ValueError as exc:
        raise ConfigError(source, [Issue("(top level)", str(exc), "each key may appear once per object")]) from None
    return parse_project(data, source, path.resolve(), raw)


def server_endpoint(server_ip: str) -> str:
    """The Zenoh endpoint of the paper's ``serverIP`` (bare IP, IP:port or an endpoint); raise EndpointError."""
    return str(parse_endpoint(server_ip, SERVER_PORT))


def gateway_address(project: Project, server_ip: str | None = None) -> Address:
    """Where the TCP gateway for bridge FMUs is: ``gatewayIP``, or the server's port + 1.

    ``server_ip`` overrides ``serverIP`` (a server told to listen elsewhere). Raises
    EndpointError for an address that cannot be used.
    """
    if project.gatewayIP:
        return parse_address(project.gatewayIP, GATEWAY_PORT)
    return gateway_beside(parse_endpoint(server_ip or project.serverIP, SERVER_PORT))


def gateway_endpoint(project: Project, server_ip: str | None = None) -> str:
    """``HOST:PORT`` of the TCP gateway for bridge FMUs (see :func:`gateway_address`)."""
    return str(gateway_address(project, server_ip))


def in_process_refusals(project: Project) -> dict[str, str]:
    """Each node an in-process run (``hycosim run --in-process``) cannot host, and why: one
    thread steps every node when the master releases it, so a node must be stepped by the
    master (an FMU, a Python model, a played recording)."""
    refused = {}
    for n in project.nodeLists:
        if n.asynchronous and not n.replay:
            refused[n.nodeName] = ("an asynchronous source samples on its own clock beside the run, which one "
                                   "thread stepping every node cannot give it")
        elif not (n.fmu or n.model or n.replay):
            refused[n.nodeName] = "a bridge FMU's node is stepped by another tool through the gateway"
    return refused
