"""An FMU checked against the node it plays, before its binary loads: the model description read
(FMI 1.0, 2.0 or 3.0), the interface the node uses, a binary for this platform, its clocks and
array shapes, and the node's ports, drivenVariable and parameters mapped onto its variables
(:func:`check_fmu`, which gives the :class:`FmuMapping` an instance is made from:
:class:`hycosim.fmi.instance.FmuInstance`). Every failure is an :class:`FmuError` that names the
node and, where there is one, the variable.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import fmpy
from fmpy import read_model_description
from fmpy.model_description import ModelDescription, ScalarVariable

from hycosim.core.schema import Node, PortType
from hycosim.core.hints import did_you_mean

# FMI 2 type names and their FMI 3 counterparts, per port type.
_COMPATIBLE = {
    PortType.REAL: {"Real", "Float64", "Float32"},
    PortType.INTEGER: {"Integer", "Int32", "Int64", "Int16", "Int8", "UInt32", "UInt64", "UInt16", "UInt8", "Enumeration"},
    PortType.BOOLEAN: {"Boolean"},
    PortType.STRING: {"String"},
    PortType.BINARY: {"Binary"},
}
_DRIVEN_TYPES = _COMPATIBLE[PortType.REAL] | _COMPATIBLE[PortType.INTEGER] | _COMPATIBLE[PortType.BOOLEAN]


class FmuError(RuntimeError):
    """An FMU that cannot serve as the node, or a call into it that failed."""


class FmuTerminated(FmuError):
    """The FMU asked to end the simulation (FMI 2: fmi2Discard with fmi2Terminated; FMI 3:
    terminateSimulation) at ``t``, the end of its last successful step."""

    def __init__(self, message: str, t: float):
        super().__init__(message)
        self.t = t


@dataclass(frozen=True)
class MappedPort:
    """A node's port bound to its FMU variable: the variable's name, value reference and FMI type, and
    for an array its element count."""

    port: str
    variable: str
    vr: int
    type: str
    # An array variable: how many elements it holds (flat, row-major); None for a scalar.
    size: int | None = None


def describe(path: Path) -> ModelDescription:
    """Read an FMU's model description; FmuError if the file is not a readable FMU."""
    try:
        return read_model_description(str(path))
    except FileNotFoundError:
        raise FmuError(f"{path}: no such FMU file") from None
    except Exception as exc:
        raise FmuError(f"{path}: not a readable FMU ({exc})") from None


CO_SIMULATION, MODEL_EXCHANGE = "CoSimulation", "ModelExchange"


def interface_of(md: ModelDescription, node: Node, path: Path) -> str:
    """The interface the node runs its FMU through: the one its entry names, else co-simulation
    when the FMU has it, else Model Exchange; FmuError if the FMU lacks it, or if the entry
    sets an integrator (solver, relativeTolerance, maxStep) for an FMU that runs as co-simulation."""
    name = node.nodeName
    if node.interface == MODEL_EXCHANGE:
        if md.modelExchange is None:
            raise FmuError(f"node {name!r}: {path.name} has no Model Exchange interface (co-simulation only); "
                           'leave out "interface"')
        return MODEL_EXCHANGE
    if node.interface == CO_SIMULATION or md.coSimulation is not None:
        if md.coSimulation is None:
            raise FmuError(f"node {name!r}: {path.name} has no co-simulation interface (Model Exchange only); "
                           'leave out "interface" and hycosim integrates it')
        given = [k for k in ("solver", "relativeTolerance", "maxStep") if getattr(node, k) is not None]
        if given and node.interface is None:
            raise FmuError(f"node {name!r}: {', '.join(given)} set, but {path.name} has a co-simulation interface, "
                           'which the node uses unless told: add "interface": "ModelExchange"')
        return CO_SIMULATION
    if md.modelExchange is None:
        if getattr(md, "scheduledExecution", None) is not None:
            raise FmuError(f"node {name!r}: {path.name} has only a scheduled-execution interface, which hycosim "
                           "does not run (it runs co-simulation and Model Exchange)")
        raise FmuError(f"node {name!r}: {path.name} has neither a co-simulation nor a Model Exchange interface")
    return MODEL_EXCHANGE


def check_platform(path: Path, md: ModelDescription, node: str) -> None:
    """Raise FmuError unless the FMU is FMI 1.0, 2.0 or 3.0 with a binary for this platform."""
    if not md.fmiVersion.startswith(("1.0", "2", "3")):
        raise FmuError(f"node {node!r}: {path.name} is an FMI {md.fmiVersion} FMU; hycosim runs FMI 1.0, 2.0 "
                       "and 3.0 FMUs")
    platforms = fmpy.supported_platforms(str(path))
    want = fmpy.platform_tuple if md.fmiVersion.startswith("3") else fmpy.platform
    if want not in platforms and not (md.fmiVersion.startswith("3") and fmpy.platform in platforms):
        raise FmuError(f"node {node!r}: {path.name} has binaries for {', '.join(platforms) or 'no platform'}, "
                       f"not for this one ({want})")


def _a(word: str) -> str:
    return ("an " if word[:1] in "aeiou" else "a ") + word


# The most elements an array variable may hold, whatever its dimensions say: a structural
# parameter set (or declared) far larger is refused before the FMU is instantiated.
MAX_ELEMENTS = 65_536


def shape_of(md: ModelDescription, var: ScalarVariable, parameters: dict[str, Any], path: Path) -> tuple[int, ...]:
    """The shape of an FMU variable, ``()`` for a scalar: per ``Dimension``, its fixed ``start``,
    or the value of the structural parameter it refers to (the node's ``parameters`` where they
    set it, else that parameter's start). FmuError where a dimension is not a whole number,
    is zero, or the array would hold more than MAX_ELEMENTS."""
    dims = getattr(var, "dimensions", None) or []
    if not dims:
        return ()
    by_vr = {v.valueReference: v for v in md.modelVariables if v.type.startswith(("UInt", "Int"))}
    shape = []
    for dim in dims:
        if dim.start is not None:
            size, source = dim.start, "its fixed size"
        else:
            param = by_vr.get(dim.valueReference)
            if param is None:
                raise FmuError(f"{path.name}: a dimension of variable {var.name!r} refers to value reference "
                               f"{dim.valueReference}, which is not an integer variable of the FMU")
            size = parameters.get(param.name, param.start)
            source = f"structural parameter {param.name!r}"
        whole = _whole(size)
        if whole is None:
            raise FmuError(f"{path.name}: a dimension of variable {var.name!r} ({source}) is {size!r}, "
                           "not a whole number")
        size = whole
        if size < 1:
            raise FmuError(f"{path.name}: variable {var.name!r} would have a dimension of {size} ({source}); "
                           "each must be at least 1")
        shape.append(size)
    elements = math.prod(shape)
    if elements > MAX_ELEMENTS:
        raise FmuError(f"{path.name}: variable {var.name!r} would hold {elements:,} elements (shape "
                       f"{list(shape)}); hycosim takes at most {MAX_ELEMENTS:,} per variable")
    return tuple(shape)


def _whole(value: Any) -> int | None:
    """A size as a project file (an int) or a model description (its text) gives it; None for
    anything else (a float, true, an infinity): never truncated."""
    if type(value) is int:
        return value
    if type(value) is str and value.strip().lstrip("+-").isdigit():
        return int(value)
    return None


# FMI 3 clocks by intervalVariability: time-based periodic ones tick on a fixed (or tunable)
# interval; the rest tick when the FMU or the importer says.
_PERIODIC = {"constant", "fixed", "calculated", "tunable"}


@dataclass(frozen=True)
class Clock:
    """An FMI 3 clock variable as hycosim sees it: its name, causality, and what kind it is
    (``periodic``, ``aperiodic`` or ``triggered``) with its interval and shift (s) where the
    model description gives them, its intervalVariability and its value reference."""

    name: str
    causality: str
    kind: str
    interval: float | None
    shift: float = 0.0
    variability: str = "constant"
    vr: int = 0

    def describe(self) -> str:
        """``tick (periodic, every 0.1 s)``, ``tick (periodic, every 0.1 s from 0.05 s)``, ``trip (triggered)``."""
        every = f", every {self.interval:g} s" if self.interval else ""
        shifted = f" from {self.shift:g} s" if every and self.shift else ""
        return f"{self.name} ({self.kind}{every}{shifted})"

    def refusal(self) -> str | None:
        """Why hycosim does not tick this clock, or None where it does: an input clock of a
        constant interval, periodic, ticks at t0 + shift + k·interval."""
        if self.kind == "triggered":
            return "triggered: it ticks on an event, not on a schedule; hycosim does not follow such ticks yet"
        if self.causality != "input":
            return f"an {self.causality} clock: the FMU ticks it, which hycosim does not follow yet"
        if self.variability != "constant":
            return f"its interval is {self.variability}; hycosim ticks clocks of a constant interval"
        if self.interval is None or not (math.isfinite(self.interval) and self.interval > 0):
            return "no finite interval above 0 given (intervalDecimal, or intervalCounter and resolution)"
        if not (math.isfinite(self.shift) and self.shift >= 0):
            return f"its shift {self.shift:g} s is not a finite time from the start"
        return None


def _clock_timing(path: Path) -> dict[str, tuple[float | None, float]]:
    """Each clock's interval and shift (s) as the FMU's model description declares them, in
    decimal or as counters of its resolution (fmpy reads a clock's intervalVariability but
    neither of these)."""
    import zipfile
    from xml.etree import ElementTree

    try:
        if path.is_dir():
            root = ElementTree.parse(path / "modelDescription.xml").getroot()
        else:
            with zipfile.ZipFile(path) as z:
                root = ElementTree.fromstring(z.read("modelDescription.xml"))
    except (OSError, KeyError, zipfile.BadZipFile, ElementTree.ParseError):
        return {}

    def seconds(clock: Any, what: str) -> float | None:
        decimal = _bound(clock.get(f"{what}Decimal"))
        if decimal is not None:
            return decimal
        counter, resolution = _bound(clock.get(f"{what}Counter")), _bound(clock.get("resolution"))
        return counter / resolution if counter is not None and resolution else None

    return {clock.get("name"): (seconds(clock, "interval"), seconds(clock, "shift") or 0.0)
            for clock in root.iter("Clock") if clock.get("name")}


def clocks_of(md: ModelDescription, path: Path) -> list[Clock]:
    """The clock variables of an FMI 3 FMU (``path``, described by ``md``), in their order."""
    if not any(v.type == "Clock" for v in md.modelVariables):
        return []
    timing = _clock_timing(path)
    out = []
    for v in md.modelVariables:
        if v.type != "Clock":
            continue
        variability = v.intervalVariability or "constant"
        kind = ("periodic" if variability in _PERIODIC else "triggered" if variability == "triggered" else "aperiodic")
        interval, shift = timing.get(v.name, (None, 0.0)) if kind == "periodic" else (None, 0.0)
        out.append(Clock(v.name, v.causality or "local", kind, interval, shift, variability, v.valueReference))
    return out


def clock_refusal(md: ModelDescription, path: Path, interface: str) -> str | None:
    """Why hycosim cannot run an FMU's clocks (naming each it cannot tick), or None where it
    ticks them all (or the FMU has none): co-simulation with event mode, every clock an input
    clock of a constant interval."""
    clocks = clocks_of(md, path)
    if not clocks:
        return None
    named = f"clock{'s' if len(clocks) > 1 else ''} {', '.join(c.describe() for c in clocks)}"
    if interface != CO_SIMULATION:
        return f"{path.name} has {named}; hycosim ticks clocks of co-simulation FMUs only"
    if not getattr(md.coSimulation, "hasEventMode", False):
        return (f"{path.name} has {named} but no event mode (hasEventMode), in which FMI 3 co-simulation "
                "ticks clocks")
    refused = [f"{c.name} ({c.refusal()})" for c in clocks if c.refusal()]
    if refused:
        return f"{path.name}: hycosim cannot tick clock{'s' if len(refused) > 1 else ''} {'; '.join(refused)}"
    return None


# The most ticks one step may meet: a clock far faster than the step would stall the run.
MAX_TICKS = 10_000


def clock_ticks(clocks: list[Clock], t0: float, t: float, end: float) -> list[tuple[float, list[int]]]:
    """The ticks of periodic ``clocks`` (a run from ``t0``) from t (included) to ``end`` (not:
    a tick there is the next step's), in order, each as (time, the value references of the
    clocks that tick then). A clock ticks at t0 + shift + k·interval, k = 0, 1, …, each time
    computed from k, so that no rounding accumulates over a run; ticks within 1e-9 of a step
    (relative) are one tick, at the step's end the next step's. ValueError for a clock that
    :meth:`Clock.refusal` refuses, or one that ticks more than MAX_TICKS times in the step."""
    tol = 1e-9 * max(1.0, abs(end))
    found: list[tuple[float, int]] = []
    for c in clocks:
        if c.refusal() is not None or c.interval is None:
            raise ValueError(f"clock {c.name!r} is not ticked by hycosim: {c.refusal()}")
        base = t0 + c.shift
        if base >= end - tol:
            continue  # its first tick is after this step
        # In periods from its first tick: where the step starts and ends (checked before any
        # rounds to a whole number: a tiny interval makes them huge, or infinite).
        first, last = (t - tol - base) / c.interval, (end - tol - base) / c.interval
        if not last - max(first, 0.0) <= MAX_TICKS:
            raise ValueError(f"clock {c.name!r} (every {c.interval:g} s) would tick more than {MAX_TICKS:,} times "
                             f"in the step from t={t:g} s to {end:g} s")
        k = math.ceil(first) if first > 0 else 0
        while (at := base + k * c.interval) < end - tol:
            found.append((at, c.vr))
            k += 1
    ticks: list[tuple[float, list[int]]] = []
    for at, vr in sorted(found):
        if ticks and at - ticks[-1][0] <= tol:
            ticks[-1][1].append(vr)  # clocks that tick together tick in one event mode
        else:
            ticks.append((at, [vr]))
    return ticks


def check_clocks(md: ModelDescription, node: str, path: Path, interface: str = CO_SIMULATION) -> None:
    """FmuError naming the clocks an FMU has where hycosim cannot tick them all
    (:func:`clock_refusal`): stepped without its ticks, a clocked partition would never run."""
    why = clock_refusal(md, path, interface)
    if why is not None:
        raise FmuError(f"node {node!r}: {why}")


def check_shapes(md: ModelDescription, node: str, parameters: dict[str, Any], path: Path) -> None:
    """FmuError unless every array variable of the FMU has a shape within bounds (:func:`shape_of`)
    once ``parameters`` have set its structural parameters: a dimension set to zero, or to a size
    past MAX_ELEMENTS, is named before the FMU is instantiated."""
    for var in md.modelVariables:
        if getattr(var, "dimensions", None):
            try:
                shape_of(md, var, parameters, path)
            except FmuError as exc:
                raise FmuError(f"node {node!r}: {exc}") from None


def map_ports(md: ModelDescription, node: Node, path: Path,
              parameters: dict[str, Any] | None = None) -> tuple[list[MappedPort], list[MappedPort]]:
    """Map the node's inputs and outputs onto FMU variables by name (``variable`` renames),
    each a scalar with the shape the model description and ``parameters`` (default the
    node's; they may set structural parameters) give it."""
    variables = {v.name: v for v in md.modelVariables}
    parameters = node.parameters if parameters is None else parameters

    def one(port, causalities: tuple[str, ...], kind: str) -> MappedPort:
        name = port.variable or port.name
        var: ScalarVariable | None = variables.get(name)
        if var is None:
            raise FmuError(f"node {node.nodeName!r}: {kind} {port.name!r} maps to variable {name!r}, "
                           f"which {path.name} does not have")
        if var.causality not in causalities:
            raise FmuError(f"node {node.nodeName!r}: variable {name!r} of {path.name} is {_a(var.causality)}, "
                           f"not an {kind}")
        if var.type not in _COMPATIBLE[port.type]:
            raise FmuError(f"node {node.nodeName!r}: {kind} {port.name!r} is {port.type.value} but variable "
                           f"{name!r} of {path.name} is {var.type}")
        try:
            shape = shape_of(md, var, parameters, path)
        except FmuError as exc:
            raise FmuError(f"node {node.nodeName!r}: {kind} {port.name!r}: {exc}") from None
        ours = tuple(port.shape or ())
        if shape != ours:
            # The model description says so already: refused here, not at the first point
            # where reading one value of several fails.
            theirs = f"an array of shape {list(shape)}" if shape else "a scalar"
            hint = (f'give the port "shape": {list(shape)}' if shape and not ours
                    else "give the port the variable's shape" if shape else 'leave "shape" out')
            raise FmuError(f"node {node.nodeName!r}: {kind} {port.name!r}"
                           + (f" (shape {list(ours)})" if ours else "")
                           + f" maps to variable {name!r} of {path.name}, {theirs} ({hint})")
        return MappedPort(port.name, name, var.valueReference, var.type, math.prod(shape) if shape else None)

    missing = [f"{kind} {p.name!r}" + (f" (variable {p.variable!r})" if p.variable else "")
               for kind, ports in (("input", node.input), ("output", node.output))
               for p in ports if (p.variable or p.name) not in variables]
    if missing:
        # All at once: an FMU built for other ports (an old build) usually lacks several.
        raise FmuError(f"node {node.nodeName!r}: {path.name} has no variable for {', '.join(missing)} "
                       "(an FMU built for other ports than the project names? rebuild it)")
    inputs = [one(p, ("input", "parameter"), "input") for p in node.input]
    outputs = [one(p, ("output", "local"), "output") for p in node.output]
    return inputs, outputs


def map_driven(md: ModelDescription, node: Node, path: Path) -> ScalarVariable | None:
    """The FMU variable named by the node's ``drivenVariable``: an input not mapped to a port."""
    name = node.drivenVariable
    if name is None:
        return None
    var = next((v for v in md.modelVariables if v.name == name), None)
    if var is None:
        raise FmuError(f"node {node.nodeName!r}: drivenVariable {name!r} is not a variable of {path.name}")
    if var.causality != "input":
        raise FmuError(f"node {node.nodeName!r}: drivenVariable {name!r} of {path.name} is {_a(var.causality)}, "
                       "not an input")
    if var.type not in _DRIVEN_TYPES:
        raise FmuError(f"node {node.nodeName!r}: drivenVariable {name!r} of {path.name} is {var.type}; "
                       "it must be Boolean, Integer or Real")
    if name in {p.variable or p.name for p in node.input}:
        raise FmuError(f"node {node.nodeName!r}: drivenVariable {name!r} is also an input port of the node; "
                       "the coordinator sets it, a link cannot")
    return var


def _fits(var_type: str, value: Any) -> bool:
    """Whether a JSON value can be set on a variable of this FMI type without guessing."""
    if var_type in _COMPATIBLE[PortType.REAL]:
        return type(value) in (int, float)
    if var_type == "Boolean":
        return type(value) is bool or (type(value) is int and value in (0, 1))
    if var_type == "String":
        return type(value) is str
    if var_type in _COMPATIBLE[PortType.INTEGER]:
        return type(value) is int and (value >= 0 or not var_type.startswith("UInt"))
    return True  # Binary and the like: the FMU says


def check_parameters(md: ModelDescription, node: str, parameters: dict[str, Any], path: Path) -> None:
    """Raise FmuError unless every key of ``parameters`` names a variable of the FMU and its
    value fits the variable's type (a number for a Real, a whole number for an Integer, …),
    is finite, and lies within the ``min`` and ``max`` the variable declares. An FMI 3 array
    variable takes a list of its elements (flat, row-major, or nested as its shape), its shape
    as the structural parameters among ``parameters`` set it; each element is checked so."""
    variables = {v.name: v for v in md.modelVariables}
    unknown = sorted(set(parameters) - set(variables))
    if unknown:
        raise FmuError(f"node {node!r}: parameter {', '.join(map(repr, unknown))} "
                       f"{'is not a variable' if len(unknown) == 1 else 'are not variables'} of {path.name}"
                       + did_you_mean(unknown, variables))
    for name, value in parameters.items():
        var = variables[name]
        if not getattr(var, "dimensions", None):
            _check_parameter(var, name, value, node, path)
            continue
        try:
            shape = shape_of(md, var, parameters, path)
        except FmuError as exc:
            raise FmuError(f"node {node!r}: {exc}") from None
        elements = array_elements(value, shape)
        if elements is None:
            raise FmuError(f"node {node!r}: parameter {name!r} is an array variable of {path.name} of shape "
                           f"{list(shape)}: give a list of its {math.prod(shape)} elements (row-major), or lists "
                           f"nested as its shape; {json_excerpt(value)} is neither")
        for i, element in enumerate(elements):
            _check_parameter(var, f"{name}[{i}]", element, node, path)


def array_elements(value: Any, shape: tuple[int, ...]) -> list[Any] | None:
    """The elements of an array value as a project file gives them, row-major: a flat list of
    every element, or lists nested exactly as ``shape``; None if it is neither."""
    if type(value) is not list:
        return None
    if len(value) == math.prod(shape) and not any(type(v) is list for v in value):
        return value
    return _nested_elements(value, shape) if len(shape) >= 2 else None


def _nested_elements(value: Any, shape: tuple[int, ...]) -> list[Any] | None:
    # Below the top, a row is nested as the rest of the shape: [[0, 0, 0, 0]] is no 1x2x2 array.
    if type(value) is not list or len(value) != shape[0]:
        return None
    if len(shape) == 1:
        return None if any(type(v) is list for v in value) else value
    out: list[Any] = []
    for row in value:
        inner = _nested_elements(row, shape[1:])
        if inner is None:
            return None
        out.extend(inner)
    return out


def json_excerpt(value: Any, limit: int = 60) -> str:
    """``value`` as JSON, cut to ``limit`` characters with an ellipsis: for a message."""
    text = json.dumps(value)
    return text if len(text) <= limit else text[:limit - 1] + "…"


def _check_parameter(var: ScalarVariable, name: str, value: Any, node: str, path: Path) -> None:
    """FmuError unless one value fits ``var`` (an array parameter: one of its elements, ``name``
    then ``A[3]``): its type, finite, within the declared range."""
    if not _fits(var.type, value):
        raise FmuError(f"node {node!r}: parameter {name!r} is {_a(var.type)} variable of {path.name}, "
                       f"which {json_excerpt(value)} is not")
    if type(value) is float and not math.isfinite(value):
        raise FmuError(f"node {node!r}: parameter {name!r} is {json.dumps(value)}, not a finite number")
    outside = _outside_range(var, value)
    if outside:
        raise FmuError(f"node {node!r}: parameter {name!r} is {json.dumps(value)}, {outside} that {path.name} "
                       "declares for it")


def _bound(text: Any) -> float | None:
    try:
        return float(text) if text is not None else None
    except (TypeError, ValueError):
        return None  # an FMU's own malformed bound: its values are not held to it


def _outside_range(variable: ScalarVariable, value: Any) -> str | None:
    """Where a number lies against the variable's declared ``min`` and ``max`` (an FMU may refuse,
    or clamp without a word, a value outside them), or None when within or undeclared."""
    if type(value) not in (int, float):
        return None
    low, high = _bound(getattr(variable, "min", None)), _bound(getattr(variable, "max", None))
    if low is not None and value < low:
        return f"below the minimum {low:g}"
    if high is not None and value > high:
        return f"above the maximum {high:g}"
    return None


@dataclass(frozen=True)
class FmuMapping:
    """An FMU's model description and the node's ports and driven flag mapped onto it."""

    md: ModelDescription
    inputs: list[MappedPort]
    outputs: list[MappedPort]
    driven: ScalarVariable | None
    interface: str = CO_SIMULATION
    # Its clocks, each one hycosim ticks (check_fmu refuses an FMU with any other).
    clocks: list[Clock] = field(default_factory=list)

    @property
    def capabilities(self) -> Any:
        """The model description's element of the interface used (its capability flags)."""
        return self.md.coSimulation if self.interface == CO_SIMULATION else self.md.modelExchange

    @property
    def variable_step(self) -> bool:
        """Whether the FMU takes communication steps of any length (a Model Exchange FMU does:
        the node's integrator steps it)."""
        if self.interface != CO_SIMULATION:
            return True
        return bool(getattr(self.md.coSimulation, "canHandleVariableCommunicationStepSize", False))

    def feedthrough(self) -> dict[str, set[str]]:
        """Each mapped output port → the mapped input ports it depends on directly, from the model
        structure; an output listed without ``dependencies`` depends on every input (as FMI
        says), and an output not listed there depends on none."""
        ports_of = {p.variable: p.port for p in self.inputs}
        every = set(ports_of.values())
        out: dict[str, set[str]] = {}
        for unknown in self.md.outputs:
            port = next((p.port for p in self.outputs if p.variable == getattr(unknown.variable, "name", None)), None)
            if port is None:
                continue
            if unknown.dependencies is None:
                out[port] = set(every)
            else:
                out[port] = {ports_of[v.name] for v in unknown.dependencies if v.name in ports_of}
        return out

    def start_feedthrough(self) -> dict[str, set[str]]:
        """Each mapped output port → the mapped input ports its value at the start depends on,
        for the initialisation phase: an output listed in ``InitialUnknowns`` depends on what
        that lists (every input without ``dependencies``); an output with ``initial="exact"``
        that is not listed there starts at its start value and depends on none; any other on
        what ``Outputs`` lists for it (every input where the model structure says nothing)."""
        return {port: reads for port, (reads, _) in self._start_dependencies().items()}

    def unstated_start_dependencies(self) -> list[str]:
        """The mapped output ports whose start dependencies the model structure does not state
        (no ``dependencies`` where it lists them, as pythonfmu writes unless told): taken as
        reading every input, which may make a loop at the start where the model has none."""
        return [port for port, (_, stated) in self._start_dependencies().items() if not stated]

    def _start_dependencies(self) -> dict[str, tuple[set[str], bool]]:
        ports_of = {p.variable: p.port for p in self.inputs}
        every = set(ports_of.values())
        listed = {getattr(u.variable, "name", None): u for u in self.md.initialUnknowns}
        listed_outputs = {getattr(u.variable, "name", None): u for u in self.md.outputs}
        variables = {v.name: v for v in self.md.modelVariables}
        out: dict[str, tuple[set[str], bool]] = {}
        for p in self.outputs:
            unknown = listed.get(p.variable)
            if unknown is None:
                if getattr(variables.get(p.variable), "initial", None) == "exact":
                    out[p.port] = (set(), True)
                    continue
                unknown = listed_outputs.get(p.variable)
            if unknown is None or unknown.dependencies is None:
                out[p.port] = (set(every), not every)
            else:
                out[p.port] = ({ports_of[v.name] for v in unknown.dependencies if v.name in ports_of}, True)
        return out


def check_fmu(path: Path, node: Node, parameters: dict[str, Any] | None = None) -> FmuMapping:
    """Everything checked before an FMU's binary loads: the FMU is readable, FMI 1.0, 2.0 or 3.0
    with the interface the node uses (:func:`interface_of`) and a binary for this platform,
    and the node's ports, drivenVariable and parameters (``parameters``, default the node's)
    map onto its variables. Nothing is extracted or instantiated."""
    md = describe(path)
    check_platform(path, md, node.nodeName)
    interface = interface_of(md, node, path)
    check_clocks(md, node.nodeName, path, interface)
    clocks = clocks_of(md, path)
    parameters = node.parameters if parameters is None else parameters
    inputs, outputs = map_ports(md, node, path, parameters)
    driven = map_driven(md, node, path)
    check_parameters(md, node.nodeName, parameters, path)
    check_shapes(md, node.nodeName, parameters, path)
    return FmuMapping(md, inputs, outputs, driven, interface, clocks)
