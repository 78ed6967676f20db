"""The project JSON's schema: pydantic models of the paper's keys plus hycosim's optional ones.

The paper's keys are accepted verbatim (``serverIP``, ``nodeNum``, ``nodeLists`` with
``nodeName``/``UID``/``input``/``output``, ``linkNum``, ``linkLists``). Our additions are
optional camelCase keys. Unknown keys are errors so that a typo cannot pass silently.

This module holds the shape of a project and what one entry says on its own; what spans
entries (links against ports, modes, guards, the coupling) is checked by
:mod:`hycosim.core.config`, which loads project files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictFloat, StrictInt, field_validator, model_validator

from hycosim.core.scheduling import batch_nodes


FREE_MODE = "free"


class PortType(str, Enum):
    """A port's type, as the project file names it; each travels as its own msgpack type
    (``WIRE_TYPES``)."""

    REAL = "Real"
    INTEGER = "Integer"
    BOOLEAN = "Boolean"
    STRING = "String"
    BINARY = "Binary"


# A link may widen a value (an Integer count into a Real input) but never narrow it.
ASSIGNABLE = {
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


def wire_types(port: "Port") -> tuple[type, ...]:
    """The Python types a port's value has on the wire: an array port's is a list (whose
    elements :func:`array_misfit` checks)."""
    return (list,) if port.shape is not None else WIRE_TYPES[port.type]


def array_misfit(port: "Port", value: list) -> str | None:
    """What is wrong with a list as the value of array ``port`` (its length, an element's
    type, as msgpack yields them), in words; None when it fits."""
    if len(value) != port.size:
        return f"{len(value)} elements where shape {list(port.shape)} holds {port.size}"
    allowed = WIRE_TYPES[port.type]
    for i, x in enumerate(value):
        if type(x) not in allowed:
            return f"element {i} is a {type(x).__name__}, not a {port.type.value}"
    return None


_DEFAULT_START = {
    PortType.REAL: 0.0,
    PortType.INTEGER: 0,
    PortType.BOOLEAN: False,
    PortType.STRING: "",
    PortType.BINARY: b"",
}


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True, frozen=True)


# The most elements an array port may hold (the bound FMU array variables have too).
MAX_ARRAY_ELEMENTS = 65_536
# The element types an array port may have.
ARRAY_TYPES = (PortType.REAL, PortType.INTEGER, PortType.BOOLEAN)


class Port(_Strict):
    """One input or output of a node: its name, type, unit and start value, and for an FMU node the
    variable it maps to."""

    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")
    type: PortType = PortType.REAL
    unit: str | None = None
    start: Any = None
    # For FMU nodes: the FMU variable this port maps to, when its name differs.
    variable: str | None = None
    # An array port: its dimensions; values travel flattened, row-major, as one list.
    shape: tuple[StrictInt, ...] | None = None

    @field_validator("shape")
    @classmethod
    def _shape(cls, value: tuple[int, ...] | None) -> tuple[int, ...] | None:
        if value is None:
            return None
        if not value or any(type(d) is not int or d < 1 for d in value):
            raise ValueError("shape is one or more dimensions, each a whole number of at least 1")
        if math.prod(value) > MAX_ARRAY_ELEMENTS:
            raise ValueError(f"shape {list(value)} holds {math.prod(value):,} elements; "
                             f"a port holds at most {MAX_ARRAY_ELEMENTS:,}")
        return value

    @model_validator(mode="after")
    def _array(self) -> "Port":
        if self.shape is None:
            return self
        if self.type not in ARRAY_TYPES:
            raise ValueError(f"an array port holds Real, Integer or Boolean values, not {self.type.value}")
        if self.start is None:
            return self
        starts = self.start if isinstance(self.start, list) else [self.start]
        if isinstance(self.start, list) and len(starts) != self.size:
            raise ValueError(f"start has {len(starts)} values for shape {list(self.shape)} "
                             f"({self.size} elements)")
        # JSON gives the types msgpack gives: an element's start fits as its wire value does.
        wrong = next((v for v in starts if type(v) not in WIRE_TYPES[self.type]), None)
        if wrong is not None or None in starts:
            raise ValueError(f"start {wrong!r} is no {self.type.value} value")
        return self

    @property
    def size(self) -> int | None:
        """How many elements an array port holds; None for a scalar port."""
        return None if self.shape is None else math.prod(self.shape)

    def start_value(self) -> Any:
        """The value the port holds before anything is routed to it (an array's: a new list)."""
        if self.shape is not None and isinstance(self.start, list):
            return list(self.start)
        one = _DEFAULT_START[self.type] if self.start is None else self.start
        return one if self.shape is None else [one] * self.size

    def columns(self, node: str) -> list[str]:
        """The port's columns in ``values.csv``: ``node.port``, or one per element of an array,
        ``node.port[0]``, ``node.port[1]``, … (flat, row-major)."""
        label = f"{node}.{self.name}"
        return [label] if self.shape is None else [f"{label}[{i}]" for i in range(self.size)]

    def wire(self) -> str:
        """``name:Type``, ``name:Type[2,3]`` for an array: what server and node agree on."""
        dims = "" if self.shape is None else "[" + ",".join(map(str, self.shape)) + "]"
        return f"{self.name}:{self.type.value}{dims}"


def _as_port(value: Any) -> Any:
    # The paper lists ports as bare names; hycosim also takes objects with a type.
    return {"name": value} if isinstance(value, str) else value


class Node(_Strict):
    """One entry of ``nodeLists``: a node's name, UID, ports, what implements it (a model or an
    FMU), its parameters, and how it steps (its own step size, asynchronous, played back)."""

    # No leading underscore: hycosim's own keys (_server, _local) start with one. A run's folder
    # holds files named after each node ("node-NAME.stderr.txt"), and a file name has at most
    # 255 bytes.
    nodeName: str = Field(pattern=r"^[A-Za-z][A-Za-z0-9_\-]*$", max_length=200)
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
        """The node's port named ``name`` (inputs first), or None."""
        for p in (*self.input, *self.output):
            if p.name == name:
                return p
        return None

    def output_names(self) -> list[str]:
        """The node's output names, in the order its OUTPUTS carry their values."""
        return [p.name for p in self.output]

    def input_names(self) -> list[str]:
        """The node's input names, in the order a release carries their values."""
        return [p.name for p in self.input]

    def wire_ports(self) -> dict[str, list[str]]:
        """The node's ports as frames carry them, ``name:Type`` in order: what the server and a
        node must agree on, however else their copies of the project file differ."""
        return {"input": [p.wire() for p in self.input], "output": [p.wire() for p in self.output]}


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


class Initialize(_Strict):
    """The initialisation phase before the first step: each node whose outputs at the start
    depend directly on inputs is given those inputs as the links carry its peers' start
    outputs, in the order the dependencies give; a cycle of such nodes (an algebraic loop at
    the start) is swept until no output changes by more than ``tolerance``·max(1, |value|),
    at most ``maxIterations`` sweeps, or the run fails naming the loop."""

    model_config = ConfigDict(allow_inf_nan=False)
    enabled: bool = True
    tolerance: float = Field(default=1e-10, gt=0)
    maxIterations: int = Field(default=100, ge=1, le=10000)


MAX_WAIT_S = 1e6  # about 11 days: the longest wall-clock wait a project may ask for


class CoSimulation(_Strict):
    """The project's ``coSimulation`` settings: the grid (start, stop, step size), the master algorithm
    and its tolerances, real time, timeouts, waiting, recording and checkpoints."""

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
    # A node on the server's host that waits by blocking (waitStrategy) reaches it over a Unix
    # socket beside serverIP's TCP port, where serverIP is a loopback address and not TLS: less
    # CPU a frame than TCP on loopback. Where nodes poll, TCP: polling catches a frame on TCP,
    # which Zenoh's Unix socket reader hands over in two wake-ups. false: TCP always.
    localSocket: bool = True
    # How the server and each node wait for their next frame. "block": sleep in Zenoh's
    # channel until it comes. "yield": poll it first, yielding the CPU between polls
    # (core.inbox): faster when frames come quickly, slower when many more processes
    # than cores compete. "auto": "yield" for up to 2 processes per core (the server and the
    # project's nodes), else "block".
    waitStrategy: Literal["auto", "block", "yield"] = "auto"
    # How the kernel schedules each node's process (core.scheduling). "batch": as batch work
    # (Linux's SCHED_BATCH): a node woken by a release does not preempt the process on its
    # core, the server sending that release among them. "normal": the system's default.
    # "auto": "batch" where the server and the nodes outnumber the cores and the run is not
    # paced to the wall clock (realTime, asynchronous sources), else "normal".
    nodeScheduling: Literal["auto", "batch", "normal"] = "auto"
    # How ``hycosim run`` carries the frames. "zenoh": the server and each node a process of
    # its own, over Zenoh on loopback. "inprocess": the master and every node in one process,
    # each release a call (as ``hycosim run --in-process``): no sockets, no per-node restarts,
    # no asynchronous sources or bridge FMUs. ``hycosim server``/``node`` always use Zenoh.
    transport: Literal["zenoh", "inprocess"] = "zenoh"
    # The master algorithm. "jacobi": every node due at a macro-step point steps at once on the
    # outputs at that point (the paper's scheme). "gauss-seidel": within a macro step the nodes
    # step one after the other in ``order``, each on the outputs its predecessors have already
    # advanced. ``order`` (Gauss-Seidel only): every stepping node once; default: derived from
    # the links, a node after the nodes it reads from (a cycle of links must be broken here).
    coupling: Literal["jacobi", "gauss-seidel"] = "jacobi"
    order: list[str] | None = None
    # A master algorithm of the user's (hycosim.master.algorithms.Algorithm): ``module:Class``
    # or ``file.py:Class`` (relative to the project file), made with ``algorithmParameters`` as
    # keyword arguments. It takes the place of iterate and stepControl; ``coupling`` is the
    # scheme localisation (eventTolerance) retakes steps with.
    algorithm: str | None = Field(default=None, min_length=1)
    algorithmParameters: dict[str, Any] = Field(default_factory=dict)
    # Iterative coupling (Jacobi, every stepping node able to roll back): see Iterate.
    iterate: Iterate | None = None
    # The initialisation phase (consistent start outputs): see Initialize.
    initialize: Initialize = Field(default_factory=Initialize)
    # An error-controlled macro step (Jacobi, every stepping node able to roll back and to take
    # steps of any length): see StepControl. None: fixed macro steps of stepSize.
    stepControl: StepControl | None = None
    # Multi-rate runs only: release the nodes for several base steps at once where the links
    # allow it (hycosim.core.coupling.batch_span); false: one release per base point, as single-rate.
    batchReleases: bool = True

    def real_time_factor(self) -> float | None:
        """Wall seconds a simulated second takes in a paced run (``realTime``: true is 1.0), or None for
        a run as fast as it goes."""
        if self.realTime is False:
            return None
        if self.realTime is True:
            return 1.0
        return float(self.realTime) if self.realTime > 0 else None


class Event(_Strict):
    """One event of the project (Equations 5-6): while ``when`` holds, the node ``drives`` names follows
    its driver through the event's routes, until ``until`` holds."""

    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_\-]*$")
    when: str
    drives: str
    until: str
    # After a release the event fires again only once this guard has held at a macro-step
    # point. Default: once `when` has been seen not to hold, so a `when` that still holds
    # at the release does not switch straight back (guards fire on a rising edge).
    rearm: str | None = None
    description: str | None = None


def driven_by_mode(events: list[Event]) -> dict[str, tuple[str, ...]]:
    """Free running and each event's mode, each with the nodes it drives in the order its
    releases name them (the events'): what ``driven`` of every release in that mode holds, as
    the server sends it and as a node's flat path takes it."""
    return {mode: tuple(e.drives for e in events if e.name == mode) for mode in [FREE_MODE, *(e.name for e in events)]}


class Ramp(_Strict):
    """An override that moves a Real input linearly to ``to`` over ``duration`` seconds, from
    ``from`` (default: the value an override held there before, else the port's start value)."""

    to: StrictFloat | StrictInt
    duration: float = Field(gt=0)
    start: StrictFloat | StrictInt | None = Field(default=None, alias="from")


class ScenarioAction(_Strict):
    """One manipulation at time ``t`` (seconds of simulated time): ``override`` an input that a
    link feeds (with ``value``, or a ``ramp``), ``release`` it to its links again, or set a
    tunable ``parameter`` to ``value``. An overridden input is what its node sees, and a
    parameter what it steps with, from the first macro-step point at or after ``t``."""

    t: float
    override: str | None = None
    value: StrictBool | StrictInt | StrictFloat | str | list[Any] | None = None
    ramp: Ramp | None = None
    release: str | None = None
    # A tunable parameter of a node (``node.name``) set to ``value`` from the point on.
    parameter: str | None = None
    description: str | None = None

    @model_validator(mode="after")
    def _one_kind(self) -> "ScenarioAction":
        if sum(x is not None for x in (self.override, self.release, self.parameter)) != 1:
            raise ValueError("an action overrides a port ('override'), releases one ('release') or sets a "
                             "tunable parameter ('parameter'), one of them")
        if self.override is not None and (self.value is None) == (self.ramp is None):
            raise ValueError("an override gives a 'value' or a 'ramp'")
        if self.release is not None and (self.value is not None or self.ramp is not None):
            raise ValueError("a release takes no 'value' or 'ramp'")
        if self.parameter is not None and (self.value is None or self.ramp is not None
                                           or type(self.value) is list):
            raise ValueError("a parameter action gives a 'value' (a number, a bool or a string), no 'ramp'")
        return self

    @property
    def kind(self) -> str:
        """What the action does: ``override``, ``release`` or ``parameter``."""
        return "override" if self.override is not None else "release" if self.release is not None else "parameter"

    @property
    def target(self) -> str:
        """What the action acts on: the overridden or released input, or the parameter, as
        ``node.name``."""
        return self.override if self.override is not None else self.release if self.release is not None \
            else self.parameter


class ObserverEntry(_Strict):
    """An observer the server tells of every point it records (hycosim.master.observers):
    ``module:Class`` or ``file.py:Class`` (relative to the project file), made with
    ``parameters`` as keyword arguments."""

    observer: str
    parameters: dict[str, Any] = Field(default_factory=dict)


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


class Recording(_Strict):
    """How the run directory's tables (values, timing) are written: ``csv`` (values.csv,
    timing.csv) or ``parquet`` (values.parquet, timing.parquet: typed columns, in row groups;
    the ``[parquet]`` extra). ``hycosim run --record`` chooses too."""

    format: Literal["csv", "parquet"] = "csv"


class Project(_Strict):
    """A project file (the paper's JSON): the server's address, the nodes, the links, the events and the
    co-simulation settings."""

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
    # Time-triggered manipulation of inputs (fault injection); --scenario FILE gives one too.
    scenario: list[ScenarioAction] = Field(default_factory=list)
    # Observers of the points recorded, made in the server's process before the run starts.
    observers: list[ObserverEntry] = Field(default_factory=list)
    recording: Recording = Field(default_factory=Recording)
    security: Security | None = None
    description: str | None = None

    def node(self, name: str) -> Node:
        """The node named ``name``; KeyError if the project has none."""
        for n in self.nodeLists:
            if n.nodeName == name:
                return n
        raise KeyError(name)

    def modes(self) -> list[str]:
        """The run's modes: free running first, then one per event."""
        return [FREE_MODE, *(e.name for e in self.events)]

    def driven_in(self) -> dict[str, tuple[str, ...]]:
        """Each mode and the nodes it drives (:func:`driven_by_mode`)."""
        return driven_by_mode(self.events)

    def stepping_nodes(self) -> list[Node]:
        """The nodes the barrier releases and waits for (every node but the asynchronous sources)."""
        return [n for n in self.nodeLists if not n.asynchronous]

    def async_nodes(self) -> list[Node]:
        """The asynchronous sources: nodes that send samples when they have them, never released."""
        return [n for n in self.nodeLists if n.asynchronous]

    def paced_nodes(self) -> list[Node]:
        """Asynchronous nodes played back from a recording: each sends the samples the recorded
        run had received by a macro-step point before that point, so the barrier waits for it."""
        return [n for n in self.nodeLists if n.asynchronous and n.replay]

    def polls_before_blocking(self, cpus: int | None) -> bool:
        """Whether a hycosim process on a machine with ``cpus`` cores polls before it blocks."""
        return polls_before_blocking(self.coSimulation.waitStrategy, len(self.nodeLists) + 1, cpus)

    def batch_nodes(self, cpus: int | None) -> bool:
        """Whether each node's process is scheduled as batch work on a machine with ``cpus`` cores
        (``coSimulation.nodeScheduling``)."""
        paced = self.coSimulation.real_time_factor() is not None or bool(self.async_nodes())
        return batch_nodes(self.coSimulation.nodeScheduling, len(self.nodeLists) + 1, cpus, paced)


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
    # One element of an array output (flat, row-major) into a scalar input; None: the whole port.
    src_element: int | None = None

    def active(self, mode: str) -> bool:
        """Whether the route carries values in ``mode`` (a route of an event's only while that event is
        in force)."""
        return self.active_in is None or mode in self.active_in


@dataclass(frozen=True)
class Issue:
    """One problem found in a project file: where (``path``, as JSON keys joined by dots), what, and a
    hint."""

    path: str
    message: str
    hint: str = ""

    def render(self) -> str:
        """The issue as one line: its path, its message and its hint."""
        hint = f" (hint: {self.hint})" if self.hint else ""
        return f"{self.path}: {self.message}{hint}"
