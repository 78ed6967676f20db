"""The project JSON: pydantic models of the paper's keys plus hycosim's optional ones.

The paper's keys are accepted verbatim (``serverIP``, ``nodeNum``, ``nodeLists`` with
``nodeName``/``UID``/``input``/``output``, ``linkNum``, ``linkLists``). Our additions are
optional camelCase keys. Unknown keys are errors so that a typo cannot pass silently.

Loading happens in two passes: pydantic checks the shape, then :func:`check_semantics`
checks what spans entries (links against ports, modes, guards). Both report every error
with its JSON path, so one run of ``hycosim validate`` lists all that is wrong.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from functools import cached_property
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, NamedTuple

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from hycosim.core.endpoints import GATEWAY_PORT, SERVER_PORT, Address, EndpointError, gateway_beside, parse_address, parse_endpoint
from hycosim.core.guards import Guard, GuardError

if TYPE_CHECKING:
    from hycosim.core.coupling import CouplingPlan

FREE_MODE = "free"


class PortType(str, Enum):
    REAL = "Real"
    INTEGER = "Integer"
    BOOLEAN = "Boolean"
    STRING = "String"
    BINARY = "Binary"


# A link may widen a value (an Integer count into a Real input) but never narrow it.
_ASSIGNABLE = {
    PortType.REAL: {PortType.REAL, PortType.INTEGER, PortType.BOOLEAN},
    PortType.INTEGER: {PortType.INTEGER, PortType.BOOLEAN},
    PortType.BOOLEAN: {PortType.BOOLEAN},
    PortType.STRING: {PortType.STRING},
    PortType.BINARY: {PortType.BINARY},
}

# The Python types a port's values have on the wire, exactly as msgpack yields them (it never
# yields subclasses, and a bool is no int there): a Real port takes integers too.
WIRE_TYPES: dict[PortType, tuple[type, ...]] = {
    PortType.REAL: (float, int),
    PortType.INTEGER: (int,),
    PortType.BOOLEAN: (bool,),
    PortType.STRING: (str,),
    PortType.BINARY: (bytes, list),
}

_DEFAULT_START = {
    PortType.REAL: 0.0,
    PortType.INTEGER: 0,
    PortType.BOOLEAN: False,
    PortType.STRING: "",
    PortType.BINARY: b"",
}


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True, frozen=True)


class Port(_Strict):
    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")
    type: PortType = PortType.REAL
    unit: str | None = None
    start: Any = None
    # For FMU nodes: the FMU variable this port maps to, when its name differs.
    variable: str | None = None

    def start_value(self) -> Any:
        return _DEFAULT_START[self.type] if self.start is None else self.start


def _as_port(value: Any) -> Any:
    # The paper lists ports as bare names; hycosim also takes objects with a type.
    return {"name": value} if isinstance(value, str) else value


class Node(_Strict):
    # No leading underscore: hycosim's own keys (_server, _local) start with one.
    nodeName: str = Field(pattern=r"^[A-Za-z][A-Za-z0-9_\-]*$")
    UID: int = Field(ge=0)
    input: list[Port] = Field(default_factory=list)
    output: list[Port] = Field(default_factory=list)
    # What implements the node: a reference model name ("gain") or "module:Class".
    model: str | None = None
    # An FMU file (path relative to the project JSON) run through fmpy.
    fmu: str | None = None
    parameters: dict[str, Any] = Field(default_factory=dict)
    # FMU nodes: an FMU input (Boolean, Integer or Real) set to true / 1 while an event drives
    # the node and false / 0 otherwise: FMI has no call for it. Python nodes get set_mode.
    drivenVariable: str | None = None
    # Asynchronous sources publish timestamped samples instead of stepping.
    asynchronous: bool = Field(default=False, alias="async")
    rate: float | None = Field(default=None, gt=0)
    # FMU nodes: which interface of an FMU that has both ("CoSimulation" unless said), and for
    # Model Exchange how the node integrates it over each macro step.
    interface: Literal["CoSimulation", "ModelExchange"] | None = None
    solver: Literal["CVode", "Euler"] | None = None
    relativeTolerance: float | None = Field(default=None, gt=0, lt=1)
    maxStep: float | None = Field(default=None, gt=0)
    # A run directory (relative to the project JSON): the node plays back what this node
    # recorded there instead of running its model or FMU (kept in the entry, to go back to).
    replay: str | None = Field(default=None, min_length=1)
    # Multi-rate coupling: this node steps every stepSize seconds, an integer multiple of
    # coSimulation.stepSize (the base); its outputs hold between its steps. None: the base.
    stepSize: float | None = Field(default=None, gt=0, allow_inf_nan=False)

    @field_validator("input", "output", mode="before")
    @classmethod
    def _ports(cls, value: Any) -> Any:
        return [_as_port(v) for v in value] if isinstance(value, list) else value

    def port(self, name: str) -> Port | None:
        for p in (*self.input, *self.output):
            if p.name == name:
                return p
        return None

    def output_names(self) -> list[str]:
        return [p.name for p in self.output]

    def input_names(self) -> list[str]:
        return [p.name for p in self.input]

    def wire_ports(self) -> dict[str, list[str]]:
        """The node's ports as frames carry them, ``name:Type`` in order: what the server and a
        node must agree on, however else their copies of the project file differ."""
        return {"input": [f"{p.name}:{p.type.value}" for p in self.input],
                "output": [f"{p.name}:{p.type.value}" for p in self.output]}


class Link(_Strict):
    """Routes outputs of one node to inputs of another.

    Either ``from``/``to`` name ports as ``node.port``, or they name nodes and ``pairs``
    lists ``[output, input]`` pairs carried by the same link.
    """

    source: str = Field(alias="from")
    target: str = Field(alias="to")
    pairs: list[tuple[str, str]] | None = None
    activeIn: list[str] | None = None
    extrapolation: Literal["hold", "linear"] = "hold"
    # A linear transformation on the way, input = factor·output + offset (SSP's
    # LinearTransformation); Real inputs only.
    factor: float | None = Field(default=None, allow_inf_nan=False)
    offset: float | None = Field(default=None, allow_inf_nan=False)
    description: str | None = None


class Iterate(_Strict):
    """Iterative coupling: each macro step is repeated, every node rolled back, until the inputs
    routed from the step's end stop changing (each within ``tolerance``·max(1, |value|))."""

    model_config = ConfigDict(allow_inf_nan=False)
    # Takes of one step at most (the first included); a step still changing then is reported
    # with its worst port, and the run goes on with it ("continue") or ends ("stop").
    maxIterations: int = Field(default=10, ge=2, le=1000)
    tolerance: float = Field(gt=0)
    # Each retry steps on old + relaxation·(new − old): below 1 it damps a loop that overshoots.
    relaxation: float = Field(default=1.0, gt=0, le=1)
    onFailure: Literal["continue", "stop"] = "continue"
    # The degree of the polynomial each Real input of a node that can interpolate its inputs
    # (an FMI 2 FMU with canInterpolateInputs) follows over a step: through the end value the
    # iteration solves for and the values at the points before. 0 holds the end value over the
    # step (the implicit scheme, first order); n gives order n + 1, and 3 an RK4's fourth.
    interpolate: int = Field(default=0, ge=0, le=3)


class StepControl(_Strict):
    """Error-controlled macro step: a step over which a coupled input held at its start value
    was wrong by more than ``tolerance``·max(1, |value|) seconds (its change over the step times
    the step, halved: the held value's error integrated over the step) is rolled back and taken
    again shorter; steps grow while the error stays below. coSimulation.stepSize is the first
    step tried."""

    model_config = ConfigDict(allow_inf_nan=False)
    tolerance: float = Field(gt=0)
    minStep: float = Field(gt=0)
    maxStep: float = Field(gt=0)


MAX_WAIT_S = 1e6  # about 11 days: the longest wall-clock wait a project may ask for


class CoSimulation(_Strict):
    # Infinity or NaN in a time would make a run endless or its comparisons meaningless.
    model_config = ConfigDict(allow_inf_nan=False)
    stepSize: float = Field(default=0.01, gt=0)
    startTime: float = 0.0
    stopTime: float = Field(default=1.0)
    # false: as fast as possible; true or a factor: wall time = simulated time * factor.
    realTime: bool | float = False
    # Wall-clock waits (s), bounded: Zenoh takes its connect timeout in whole milliseconds as a
    # 64-bit integer, and a wait of years is a typo.
    stepTimeout: float = Field(default=10.0, gt=0, le=MAX_WAIT_S)
    # Locate guard crossings to within this many seconds by rolling steps back (when every
    # stepping node can save and restore its state); None: fixed macro steps.
    eventTolerance: float | None = Field(default=None, gt=0)
    attachTimeout: float = Field(default=30.0, gt=0, le=MAX_WAIT_S)
    # Take a checkpoint of the whole co-simulation every this many seconds of simulated time
    # (at the first macro-step point at or after each multiple, and at the start). A node
    # process that dies is then started again and the run goes on from the last checkpoint;
    # a server that dies goes on with --resume. None: no checkpoints, a lost node ends the run.
    checkpointEvery: float | None = Field(default=None, gt=0)
    # A node (or the server) whose link drops may come back within this many seconds and
    # the run resumes without losing a step; 0: a lost node stops the run at once.
    linkGrace: float = Field(default=0.0, ge=0, le=MAX_WAIT_S)
    # Zenoh's low-latency unicast transport: about 1.5x the macro steps/s of the standard one
    # on loopback, but it cannot fragment, so every frame must stay within
    # core.session.LOW_LATENCY_MAX_FRAME bytes. false: standard transport, any size.
    lowLatency: bool = True
    # How the server and each node wait for their next frame. "block": sleep in Zenoh's
    # channel until it comes. "yield": poll it first, yielding the CPU between polls
    # (core.inbox): faster when frames come quickly, slower when many more processes
    # than cores compete. "auto": "yield" for up to 2 processes per core (the server and the
    # project's nodes), else "block".
    waitStrategy: Literal["auto", "block", "yield"] = "auto"
    # The master algorithm. "jacobi": every node due at a macro-step point steps at once on the
    # outputs at that point (the paper's scheme). "gauss-seidel": within a macro step the nodes
    # step one after the other in ``order``, each on the outputs its predecessors have already
    # advanced. ``order`` (Gauss-Seidel only): every stepping node once; default: derived from
    # the links, a node after the nodes it reads from (a cycle of links must be broken here).
    coupling: Literal["jacobi", "gauss-seidel"] = "jacobi"
    order: list[str] | None = None
    # Iterative coupling (Jacobi, every stepping node able to roll back): see Iterate.
    iterate: Iterate | None = None
    # An error-controlled macro step (Jacobi, every stepping node able to roll back and to take
    # steps of any length): see StepControl. None: fixed macro steps of stepSize.
    stepControl: StepControl | None = None
    # Multi-rate runs only: release the nodes for several base steps at once where the links
    # allow it (hycosim.core.coupling.batch_span); false: one release per base point, as single-rate.
    batchReleases: bool = True

    def real_time_factor(self) -> float | None:
        if self.realTime is False:
            return None
        if self.realTime is True:
            return 1.0
        return float(self.realTime) if self.realTime > 0 else None


class Event(_Strict):
    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_\-]*$")
    when: str
    drives: str
    until: str
    # After a release the event fires again only once this guard has held at a macro-step
    # point. Default: once `when` has been seen not to hold, so a `when` that still holds
    # at the release does not switch straight back (guards fire on a rising edge).
    rearm: str | None = None
    description: str | None = None


class Tls(_Strict):
    """TLS on the server's ``tls/HOST:PORT`` endpoint; PEM files relative to the project JSON."""

    # The CA that signed the server's certificate: what a node checks the server against.
    rootCa: str
    # The server's certificate (naming serverIP's host) and private key; only the server reads them.
    certificate: str | None = None
    privateKey: str | None = None


class Security(_Strict):
    """Remote attach: Zenoh user/password with per-node access control, TLS, or both."""

    # Zenoh's dictionary file, "user:password" per line: "server", each node by its name,
    # and any other user (a monitor for `hycosim status`). Relative to the project JSON.
    credentials: str | None = None
    # Access control at the router (with credentials): each node may publish only on its own keys.
    acl: bool = True
    tls: Tls | None = None


class Project(_Strict):
    # The JSON Schema an editor validates and completes the file against (hycosim schema); not read.
    schema_ref: str | None = Field(default=None, alias="$schema")
    projectName: str = Field(default="project", pattern=r"^[A-Za-z0-9_\-]+$")
    serverIP: str = "127.0.0.1"
    # The TCP gateway for bridge FMUs (HOST:PORT); default: serverIP's host, port + 1.
    gatewayIP: str | None = None
    nodeNum: int = Field(ge=1)
    nodeLists: list[Node]
    linkNum: int = Field(default=0, ge=0)
    linkLists: list[Link] = Field(default_factory=list)
    coSimulation: CoSimulation = Field(default_factory=CoSimulation)
    events: list[Event] = Field(default_factory=list)
    security: Security | None = None
    description: str | None = None

    def node(self, name: str) -> Node:
        for n in self.nodeLists:
            if n.nodeName == name:
                return n
        raise KeyError(name)

    def modes(self) -> list[str]:
        return [FREE_MODE, *(e.name for e in self.events)]

    def stepping_nodes(self) -> list[Node]:
        return [n for n in self.nodeLists if not n.asynchronous]

    def async_nodes(self) -> list[Node]:
        return [n for n in self.nodeLists if n.asynchronous]

    def paced_nodes(self) -> list[Node]:
        """Asynchronous nodes played back from a recording: each sends the samples the recorded
        run had received by a macro-step point before that point, so the barrier waits for it."""
        return [n for n in self.nodeLists if n.asynchronous and n.replay]

    def polls_before_blocking(self, cpus: int | None) -> bool:
        """Whether a hycosim process on a machine with ``cpus`` cores polls before it blocks."""
        return polls_before_blocking(self.coSimulation.waitStrategy, len(self.nodeLists) + 1, cpus)


def project_json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of the project file, from the models above: what ``hycosim
    schema`` writes and project files may name with ``"$schema"``. A port may also be given as
    its bare name, which the models take before they check (``_as_port``)."""
    schema = Project.model_json_schema(by_alias=True)
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "hycosim project"
    port_name = Port.model_fields["name"].metadata[0].pattern
    for key in ("input", "output"):
        schema["$defs"]["Node"]["properties"][key]["items"] = {
            "anyOf": [{"$ref": "#/$defs/Port"}, {"type": "string", "pattern": port_name}]}
    return schema


def polls_before_blocking(strategy: str, processes: int, cpus: int | None) -> bool:
    """Resolve a ``waitStrategy`` for ``processes`` co-simulation processes on ``cpus`` cores.

    Polling pays when the frame awaited comes while the poller yields its core to the peer
    that sends it; with many more runnable processes than cores every yield is one more
    context switch. Measured on 2 cores (barrier benchmark, 3 to 17 processes): polling
    gave +20 to +50 % macro steps/s at 3 and 5 processes, lost a sixth at 9 and a fifth
    at 17. On the same VM from 2026-11-26 on it paid nowhere: even at 3 and 4 processes,
    and at 5 it lost 4 to 9 % in each of three sessions; hence up to two processes per core.
    """
    if strategy == "auto":
        return processes <= 2 * (cpus or 1)
    return strategy == "yield"


@dataclass(frozen=True)
class Route:
    """One output→input pair of a link, resolved against the nodes."""

    link_index: int
    src_node: str
    src_port: str
    dst_node: str
    dst_port: str
    active_in: frozenset[str] | None  # None: active in every mode
    extrapolation: str
    # (factor, offset) of a linear transformation; None: the value as it is.
    transform: tuple[float, float] | None = None

    def active(self, mode: str) -> bool:
        return self.active_in is None or mode in self.active_in


@dataclass(frozen=True)
class Issue:
    path: str
    message: str
    hint: str = ""

    def render(self) -> str:
        hint = f" (hint: {self.hint})" if self.hint else ""
        return f"{self.path}: {self.message}{hint}"


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
        return self.project.projectName

    @cached_property
    def coupling(self) -> CouplingPlan:
        """How the stepping nodes are coupled: their rates and, for Gauss-Seidel, their order."""
        from hycosim.core.coupling import plan  # it reads Project and Route, defined here

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


def _pydantic_issues(err: ValidationError) -> list[Issue]:
    issues = []
    for e in err.errors():
        path = ""
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
            pairs = [(link.source, o, link.target, n) for o, n in link.pairs]
        for j, (sn, sp, dn, dp) in enumerate(pairs):
            pw = where if link.pairs is None else f"{where}.pairs[{j}]"
            ok = True
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
            st, dt = nodes[sn].port(sp).type, nodes[dn].port(dp).type
            if st not in _ASSIGNABLE[dt]:
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
            routes.append(Route(i, sn, sp, dn, dp, active, link.extrapolation, transform))
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
            compiled[key] = g
        if len(compiled) == len(given):
            guards[e.name] = EventGuards(**compiled)
    routes = _resolve_routes(project, issues)
    from hycosim.core.coupling import coupling_issues  # it reads Project and Route, defined here

    issues.extend(coupling_issues(project, routes))
    return routes, guards, issues


def parse_project(data: Any, source: str = "<config>", path: Path | None = None, raw: bytes = b"") -> LoadedProject:
    """Validate an already-decoded project document; raise ConfigError listing every problem."""
    try:
        project = Project.model_validate(data)
    except ValidationError as err:
        raise ConfigError(source, _pydantic_issues(err)) from None
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
