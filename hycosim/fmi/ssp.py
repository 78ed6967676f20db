"""SSP packages (the Modelica Association's System Structure and Parameterization) in and out.

In: FMPy's reader (``fmpy.ssp.ssd``) checks ``SystemStructure.ssd`` against the SSP 1.0
schema FMPy ships and gives the structure: systems, components, connectors, connections and
parameter bindings, inline or in ``.ssv`` files. What it leaves out is read here from the
XML: the default experiment (with the macro step a package hycosim wrote keeps in an
annotation: SSP 1.0 has no word for it) and the transformation of each connection (FMPy
looks for it in the ``ssd`` namespace; the schema puts it in ``ssc``).
Nested systems are flattened: a component's node is named by its path below the root
system joined with ``_`` (a ``.`` would read as ``node.port``), and a signal that passes
through the connectors of systems is followed from the component that writes it to the
component that reads it, its transformations composed on the way. Every element hycosim
cannot represent is named with its path in the package, never skipped.

Out: a project whose nodes are all FMUs becomes a package that FMPy's ``simulate_ssp`` and
:func:`read_ssp` read back.
"""

from __future__ import annotations

import re
import shutil
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any, Iterable
from xml.etree import ElementTree as ET

from hycosim.core.folders import make_folder

NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}
SSD = "SystemStructure.ssd"
# SSP 1.0 has no word for a macro step: a package hycosim writes keeps it in an annotation.
ANNOTATION = "org.hycosim"
HYCOSIM_NS = "https://hycosim.org/ssp"
FMU_TYPE = "application/x-fmu-sharedlibrary"
# The name of every component's parameter set in an exported package: one name across the
# package, since a tool may apply sets by name to every component at once (ECOS's
# ``init(parameter_set=...)``).
PARAMETER_SET = "parameters"
_PORT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class SspError(RuntimeError):
    """A package that cannot be read, or holds what hycosim cannot represent; names the package and the paths."""


@dataclass
class Component:
    """A component of the flattened system: an FMU in the package."""

    path: str  # "Sub.Comp": the systems below the root, then the component
    node: str  # the node's name: the path with "_" for "."
    source: str  # the FMU's entry in the package
    connectors: list[tuple[str, str]]  # (name, kind)
    parameters: dict[str, Any] = field(default_factory=dict)


@dataclass
class Signal:
    """One flattened connection: a component's output to another's input, y = factor·x + offset."""

    src: tuple[str, str]  # (component path, connector)
    dst: tuple[str, str]
    factor: float = 1.0
    offset: float = 0.0
    units_as_they_are: bool = False  # a connection on the way says suppressUnitConversion


@dataclass
class SspSystem:
    """What a package holds, flattened."""

    name: str
    components: list[Component]
    signals: list[Signal]
    start_time: float | None
    stop_time: float | None
    step_size: float | None


def _attr(element: Any, name: str) -> str | None:
    return element.get(name)


def read_ssp(path: Path) -> SspSystem:
    """The system in the package at ``path``, flattened; SspError naming every problem (the package
    unreadable or invalid, an FMU missing from it, an element hycosim cannot represent)."""
    try:
        with zipfile.ZipFile(path) as z:
            names = set(z.namelist())
            if SSD not in names:
                raise SspError(f"{path}: no {SSD} in the package (entries: {', '.join(sorted(names)[:8])})")
            xml = z.read(SSD)
    except (OSError, zipfile.BadZipFile) as exc:
        raise SspError(f"{path}: not an SSP package ({exc})") from None
    from fmpy.ssp import ssd as fmpy_ssd

    try:
        ssd = fmpy_ssd.read_ssd(str(path), validate=True)
    except Exception as exc:  # FMPy raises a bare Exception with the schema's messages, or lxml's own
        lines = str(exc).splitlines()
        raise SspError(f"{path}: {SSD} does not validate against the SSP schema: "
                       f"{'; '.join(lines[1:4] or lines[:1])}") from None
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as exc:
        raise SspError(f"{path}: {SSD} is not XML ({exc})") from None
    problems: list[str] = []
    components: list[Component] = []
    edges: list[tuple[_Connector, _Connector, float, float, bool]] = []  # start → end, y = factor·x + offset
    kinds: dict[_Connector, str] = {}  # a component's connector → its kind
    _walk(ssd.system, root.find("ssd:System", NS), "", names, components, edges, kinds, problems)
    units = _units(root.find("ssd:System", NS), "")
    experiment = root.find("ssd:DefaultExperiment", NS)
    start = _number(experiment, "startTime", problems, "DefaultExperiment") if experiment is not None else None
    stop = _number(experiment, "stopTime", problems, "DefaultExperiment") if experiment is not None else None
    step = None
    ours = root.find(f"ssd:DefaultExperiment/ssd:Annotations/ssc:Annotation[@type='{ANNOTATION}']/hycosim:coSimulation",
                     {**NS, "hycosim": HYCOSIM_NS})
    if ours is not None:
        step = _number(ours, "stepSize", problems, f"DefaultExperiment/Annotations/Annotation[{ANNOTATION}]")
    signals = _signals(edges, kinds, problems)
    for s in signals:
        if units.get(s.src) and units.get(s.dst) and units[s.src] != units[s.dst] and not s.units_as_they_are:
            problems.append(f"connection {_show(s.src)} → {_show(s.dst)}: a unit conversion from "
                            f"{units[s.src]} to {units[s.dst]} (hycosim converts no units: give both ends one unit, or "
                            'a LinearTransformation that converts and suppressUnitConversion="true")')
    if problems:
        raise SspError(f"{path}: {len(problems)} thing(s) hycosim cannot represent:\n  " + "\n  ".join(problems))
    return SspSystem(ssd.name or root.get("name") or path.stem, components, signals, start, stop, step)


def _units(system: Any, prefix: str) -> dict[_Connector, str]:
    """The unit of every component connector that names one (``<ssc:Real unit=...>``), by connector."""
    found = {}
    for comp in system.findall("ssd:Elements/ssd:Component", NS):
        for c in comp.findall("ssd:Connectors/ssd:Connector", NS):
            real = c.find("ssc:Real", NS)
            if real is not None and real.get("unit"):
                found[(f"{prefix}{comp.get('name')}", c.get("name"))] = real.get("unit")
    for sub in system.findall("ssd:Elements/ssd:System", NS):
        found.update(_units(sub, f"{prefix}{sub.get('name')}."))
    return found


def _number(element: Any, name: str, problems: list[str], where: str) -> float | None:
    text = element.get(name)
    if text is None:
        return None
    try:
        return float(text)
    except ValueError:
        problems.append(f"{where}: {name}={text!r} is not a number")
        return None


# A connector: (the path of its component or system, "" for the root system; its name).
_Connector = tuple[str, str]


def _walk(system: Any, xml: Any, prefix: str, names: set[str], components: list[Component],
          edges: list[tuple[_Connector, _Connector, float, float, bool]], kinds: dict[_Connector, str],
          problems: list[str]) -> None:
    """Collect the components and connections of ``system`` (FMPy's object, ``xml`` its element) and below."""
    from fmpy.ssp.ssd import Component as FmpyComponent, SignalDictionaryReference, System as FmpySystem

    where = f"System[{system.name}]" if not prefix else f"System[{prefix.rstrip('.')}]"
    here = prefix  # "" at the root; "Sub." below
    if system.parameterBindings:
        problems.append(f"{where}/ParameterBindings: bindings on a system (hycosim binds parameters per component)")
    if system.signalDictionaries:
        problems.append(f"{where}/SignalDictionaries: signal dictionaries")
    for element in system.elements:
        if isinstance(element, SignalDictionaryReference):
            problems.append(f"{where}/Elements/SignalDictionaryReference[{element.name}]: signal dictionaries")
        elif isinstance(element, FmpySystem):
            sub_xml = xml.find(f"ssd:Elements/ssd:System[@name='{element.name}']", NS)
            _walk(element, sub_xml, f"{here}{element.name}.", names, components, edges, kinds, problems)
        elif isinstance(element, FmpyComponent):
            components.append(_component(element, f"{here}{element.name}", names, kinds, problems,
                                         f"{where}/Elements/Component[{element.name}]"))
    connectors = {None: {c.name for c in system.connectors}}
    connectors.update({e.name: {c.name for c in e.connectors} for e in system.elements})
    for c in xml.findall("ssd:Connections/ssd:Connection", NS):
        label = (f"{where}/Connections/Connection[{c.get('startElement') or ''}.{c.get('startConnector')} → "
                 f"{c.get('endElement') or ''}.{c.get('endConnector')}]")
        unknown = [f"{e or 'the system'} has no connector {n!r}" if e in connectors else f"no element {e!r}"
                   for e, n in ((c.get("startElement"), c.get("startConnector")),
                                (c.get("endElement"), c.get("endConnector")))
                   if n not in connectors.get(e, set())]
        if unknown:
            problems.append(f"{label}: {'; '.join(unknown)}")
            continue
        factor, offset = 1.0, 0.0
        linear = c.find("ssc:LinearTransformation", NS)
        if linear is not None:
            given = _number(linear, "factor", problems, label)
            factor = 1.0 if given is None else given
            given = _number(linear, "offset", problems, label)
            offset = 0.0 if given is None else given
        for other in ("BooleanMappingTransformation", "IntegerMappingTransformation",
                      "EnumerationMappingTransformation"):
            if c.find(f"ssc:{other}", NS) is not None:
                problems.append(f"{label}: {other} (hycosim transforms Real signals linearly only)")
        own = here.rstrip(".")
        start = f"{here}{c.get('startElement')}" if c.get("startElement") else own
        end = f"{here}{c.get('endElement')}" if c.get("endElement") else own
        edges.append(((start, c.get("startConnector")), (end, c.get("endConnector")), factor, offset,
                      c.get("suppressUnitConversion") in ("true", "1")))


def _component(element: Any, path: str, names: set[str], kinds: dict[_Connector, str], problems: list[str],
               where: str) -> Component:
    source = element.source or ""
    if element.type not in (None, FMU_TYPE):
        problems.append(f"{where}: a component of type {element.type!r} (hycosim runs FMUs, {FMU_TYPE})")
    elif source not in names:
        problems.append(f"{where}: its FMU {source!r} is not in the package")
    parameters: dict[str, Any] = {}
    for b, binding in enumerate(element.parameterBindings):
        if binding.parameterMapping and any(m.mappingEntries for m in binding.parameterMapping):
            problems.append(f"{where}/ParameterBindings/ParameterBinding[{b + 1}]: a parameter mapping (ssm)")
        prefix = binding.prefix or ""
        for parameter_set in binding.parameterValues:
            for p in parameter_set.parameters:
                name = p.name[len(prefix):] if prefix and p.name.startswith(prefix) else p.name
                try:
                    parameters[name] = _value(p.type, p.value)
                except ValueError as exc:
                    problems.append(f"{where}/ParameterBindings/ParameterBinding[{b + 1}]/Parameter[{p.name}]: {exc}")
    for connector in element.connectors:
        kinds[(path, connector.name)] = connector.kind
    return Component(path, path.replace(".", "_"), source, [(c.name, c.kind) for c in element.connectors], parameters)


def _value(kind: str | None, text: str | None) -> Any:
    if text is None:
        raise ValueError("no value")
    if kind == "Real":
        return float(text)
    if kind in ("Integer", "Enumeration"):
        return int(text)
    if kind == "Boolean":
        if text not in ("true", "false", "1", "0"):
            raise ValueError(f"{text!r} is not a Boolean")
        return text in ("true", "1")
    if kind == "String":
        return text
    raise ValueError(f"a {kind} parameter (hycosim sets Real, Integer, Boolean, String and Enumeration ones)")


def _signals(edges: list[tuple[_Connector, _Connector, float, float, bool]], kinds: dict[_Connector, str],
             problems: list[str]) -> list[Signal]:
    """Each component input fed through the connections, followed back to the component output
    that writes it through any system connectors between, transformations composed."""
    feeding: dict[_Connector, list[tuple[_Connector, float, float, bool]]] = {}
    for start, end, factor, offset, plain in edges:
        feeding.setdefault(end, []).append((start, factor, offset, plain))
    signals = []
    for end, kind in kinds.items():
        if kind not in ("input", "parameter", "inout"):
            continue
        chain = feeding.get(end)
        if not chain:
            continue
        if kind != "input":
            problems.append(f"connector {_show(end)}: a {kind} connector fed by a connection "
                            "(hycosim routes outputs to inputs)")
            continue
        # end = factor·(the value at `at`) + offset, walking back one connection at a time.
        at, factor, offset, plain, seen = end, 1.0, 0.0, False, {end}
        while True:
            sources = feeding.get(at, [])
            if len(sources) != 1:
                problems.append(f"connector {_show(end)}: {_show(at)} is fed by {len(sources)} connections")
                break
            at, f, o, p = sources[0]
            factor, offset, plain = factor * f, factor * o + offset, plain or p
            if at in kinds:  # a component's connector: the signal's source
                if kinds[at] not in ("output", "calculatedParameter", "inout"):
                    problems.append(f"connector {_show(end)}: fed by {_show(at)}, a {kinds[at]} connector")
                else:
                    signals.append(Signal(at, end, factor, offset, plain))
                break
            if at in seen:
                problems.append(f"connector {_show(end)}: its connections form a loop through {_show(at)}")
                break
            seen.add(at)
    return signals


def _show(connector: _Connector) -> str:
    return f"{connector[0]}.{connector[1]}" if connector[0] else connector[1]


# FMI variable types → port types.
_PORT_TYPES = {"Real": "Real", "Float64": "Real", "Float32": "Real", "Boolean": "Boolean", "String": "String",
               "Binary": "Binary"}


def _port_type(fmi_type: str) -> str:
    return _PORT_TYPES.get(fmi_type, "Integer")  # Integer, Int8…UInt64, Enumeration


def _plain(text: str) -> str:
    """``text`` as an FMU's file name: letters, digits, '_', '-' and inner dots, ending in
    '.fmu'; no folder, no hidden file, never '.fmu' alone."""
    name = re.sub(r"[^A-Za-z0-9_.\-]", "_", text).strip(".")
    name = name[:-4] if name.lower().endswith(".fmu") else name
    return f"{name.rstrip('.') or 'component'}.fmu"


def fmu_file_names(sources: Iterable[str]) -> dict[str, str]:
    """A file name for each FMU entry of a package (``sources``: entry names, repeats allowed),
    distinct for distinct entries (in any letter case): the entry's own name where it is free, else the entry's
    folders joined into it with ``_``, else that with ``-2``, ``-3``... before ``.fmu``
    (added where the entry's name lacks it).
    A component that shares another's entry shares its file."""
    names: dict[str, str] = {}
    taken: set[str] = set()  # lower case: on a case-insensitive disk A.fmu is a.fmu
    for source in dict.fromkeys(sources):
        name = _plain(PurePosixPath(source).name)
        if name.lower() in taken:
            name = _plain(source)
        base, k = name[:-4], 2
        while name.lower() in taken:
            name, k = f"{base}-{k}.fmu", k + 1
        names[source] = name
        taken.add(name.lower())
    return names


def project_from_ssp(path: Path, fmu_dir: Path, *, side: dict[str, Any] | None = None,
                     step: float | None = None, stop: float | None = None) -> dict[str, Any]:
    """The project JSON (as a dict) for the package at ``path``, with its FMUs extracted into
    ``fmu_dir`` (named relative to ``fmu_dir.parent``, where the project file goes). ``side``: the
    parts SSP has no word for (serverIP, events, asynchronous nodes, coSimulation keys), merged
    in; ``step``/``stop``: the macro step and stop time when the package gives none.
    SspError naming the package and what is wrong."""
    from hycosim.fmi.loader import FmuError, describe

    system = read_ssp(path)
    staging = Path(tempfile.mkdtemp(prefix="hycosim-ssp-"))  # into fmu_dir only once all is well
    problems: list[str] = []
    nodes: list[dict[str, Any]] = []
    port_of: dict[tuple[str, str], str] = {}
    fed = {s.dst for s in system.signals}
    names = fmu_file_names(c.source for c in system.components)
    with zipfile.ZipFile(path) as z:
        for uid, comp in enumerate(system.components, start=1):
            staged = staging / names[comp.source]
            if not staged.exists():  # streamed: an FMU may be larger than memory should hold
                with z.open(comp.source) as src, staged.open("wb") as dst:
                    shutil.copyfileobj(src, dst, 1 << 20)
            try:
                variables = {v.name: v for v in describe(staged).modelVariables}
            except FmuError as exc:
                problems.append(f"component {comp.path}: {exc}")
                continue
            target = fmu_dir / staged.name
            node = {"nodeName": comp.node, "UID": uid, "fmu": str(target.relative_to(fmu_dir.parent)),
                    "input": [], "output": []}
            for name, kind in comp.connectors:
                key = "output" if kind in ("output", "calculatedParameter") else "input" if (comp.path, name) in fed \
                    else None
                if key is None:
                    continue
                var = variables.get(name)
                if var is None:
                    problems.append(f"component {comp.path}: connector {name!r} is no variable of {comp.source}")
                    continue
                port = name if _PORT.fullmatch(name) else re.sub(r"\W", "_", name).lstrip("0123456789") or "port"
                if any(p["name"] == port for p in node["input"] + node["output"]):
                    problems.append(f"component {comp.path}: connectors {name!r} and another both make port {port!r}")
                    continue
                entry = {"name": port, "type": _port_type(var.type)}
                if port != name:
                    entry["variable"] = name
                node[key].append(entry)
                port_of[(comp.path, name)] = port
            if comp.parameters:
                node["parameters"] = dict(comp.parameters)
            nodes.append(node)
    by_path = {c.path: c.node for c in system.components}
    links = []
    for s in system.signals:
        if s.src not in port_of or s.dst not in port_of:
            continue  # its connector is named above
        link: dict[str, Any] = {"from": f"{by_path[s.src[0]]}.{port_of[s.src]}",
                                "to": f"{by_path[s.dst[0]]}.{port_of[s.dst]}"}
        if (s.factor, s.offset) != (1.0, 0.0):
            link.update(factor=s.factor, offset=s.offset)
        links.append(link)
    cosim: dict[str, Any] = {}
    for key, value in (("startTime", system.start_time), ("stopTime", system.stop_time if stop is None else stop),
                       ("stepSize", system.step_size if step is None else step)):
        if value is not None:
            cosim[key] = value
    cosim.update((side or {}).get("coSimulation", {}))
    for key, where in (("stopTime", "a DefaultExperiment stopTime"), ("stepSize", "macro step (SSP 1.0 has none)")):
        if key not in cosim:
            problems.append(f"no {key}: the package has no {where}; give --{key[:4].lower()} or coSimulation.{key} "
                            "in the side file")
    if problems:
        shutil.rmtree(staging, ignore_errors=True)
        raise SspError(f"{path}: " + "; ".join(problems))
    make_folder(fmu_dir)
    for staged in staging.iterdir():
        shutil.move(str(staged), fmu_dir / staged.name)
    staging.rmdir()
    name = re.sub(r"[^A-Za-z0-9_\-]", "_", system.name) or "ssp"
    project: dict[str, Any] = {"projectName": name, "description": f"imported from {path.name}",
                               "serverIP": "127.0.0.1:7447", "nodeNum": len(nodes), "nodeLists": nodes,
                               "linkNum": len(links), "linkLists": links, "coSimulation": cosim}
    for key, value in (side or {}).items():
        if key in ("nodeLists", "linkLists", "events"):
            project[key] = project.get(key, []) + list(value)
        elif key != "coSimulation":
            project[key] = value
    project["nodeNum"], project["linkNum"] = len(project["nodeLists"]), len(project["linkLists"])
    return project


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}" if prefix in NS else f"{{{HYCOSIM_NS}}}{tag}"


def export_problems(project: Any) -> list[str]:
    """What in ``project`` (a config.Project) SSP 1.0 cannot hold, by JSON path (empty if nothing)."""
    found = []
    for i, n in enumerate(project.nodeLists):
        where = f"nodeLists[{i}] ({n.nodeName})"
        if not n.fmu:
            found.append(f"{where}: not an FMU node (a package holds FMUs)")
        if n.asynchronous:
            found.append(f"{where}: asynchronous")
        if n.replay:
            found.append(f"{where}: replay")
        if n.drivenVariable or n.interface or n.solver or n.relativeTolerance or n.maxStep:
            found.append(f"{where}: drivenVariable, interface or solver settings")
        arrays = [p.name for p in (*n.input, *n.output) if p.shape is not None]
        if arrays:  # SSP 1.0 connectors are scalars
            found.append(f"{where}: array port{'s' if len(arrays) > 1 else ''} {', '.join(arrays)}")
        listed = [k for k, v in n.parameters.items() if type(v) is list]
        if listed:  # SSP 1.0 parameters are scalars too
            found.append(f"{where}: array parameter{'s' if len(listed) > 1 else ''} {', '.join(listed)}")
    for i, link in enumerate(project.linkLists):
        if link.activeIn is not None:
            found.append(f"linkLists[{i}]: activeIn (modes)")
        if link.extrapolation != "hold":
            found.append(f"linkLists[{i}]: extrapolation")
    if project.events:
        found.append(f"events: {', '.join(e.name for e in project.events)}")
    return found


def write_ssp(loaded: Any, out: Path) -> Path:
    """Write the project (a config.LoadedProject whose nodes are all FMUs) as an SSP 1.0 package:
    components with their FMUs, connectors typed, parameters bound inline, input start values
    as parameters, one connection per route (with a LinearTransformation where the link has
    one), the default experiment and, in an annotation, the macro step. SspError naming what
    SSP cannot hold."""
    project = loaded.project
    problems = export_problems(project)
    if problems:
        raise SspError(f"{loaded.path}: SSP cannot hold: " + "; ".join(problems))
    for prefix, uri in NS.items():
        ET.register_namespace(prefix, uri)
    ET.register_namespace("hycosim", HYCOSIM_NS)
    root = ET.Element(_q("ssd", "SystemStructureDescription"), version="1.0", name=project.projectName)
    system = ET.SubElement(root, _q("ssd", "System"), name=project.projectName)
    elements = ET.SubElement(system, _q("ssd", "Elements"))
    files: dict[str, Path] = {}
    for n in project.nodeLists:
        path = loaded.resolve(n.fmu)
        source = f"resources/{path.name}"
        if files.setdefault(source, path) != path:
            raise SspError(f"{loaded.path}: two FMUs named {path.name} ({files[source]}, {path}); rename one")
        comp = ET.SubElement(elements, _q("ssd", "Component"), name=n.nodeName, source=source, type=FMU_TYPE)
        connectors = ET.SubElement(comp, _q("ssd", "Connectors"))
        for kind, ports in (("input", n.input), ("output", n.output)):
            for p in ports:
                c = ET.SubElement(connectors, _q("ssd", "Connector"), name=p.variable or p.name, kind=kind)
                ET.SubElement(c, _q("ssc", p.type.value))
        values = {**{p.variable or p.name: (p.type.value, p.start) for p in n.input if p.start is not None},
                  **{k: (_ssv_type(v), v) for k, v in n.parameters.items()}}
        if values:
            binding = ET.SubElement(ET.SubElement(comp, _q("ssd", "ParameterBindings")), _q("ssd", "ParameterBinding"))
            pset = ET.SubElement(ET.SubElement(binding, _q("ssd", "ParameterValues")), _q("ssv", "ParameterSet"),
                                 version="1.0", name=PARAMETER_SET)
            params = ET.SubElement(pset, _q("ssv", "Parameters"))
            for name, (kind, value) in values.items():
                text = ("true" if value else "false") if kind == "Boolean" else repr(value) if kind == "Real" else str(value)
                ET.SubElement(ET.SubElement(params, _q("ssv", "Parameter"), name=name), _q("ssv", kind), value=text)
    connections = ET.SubElement(system, _q("ssd", "Connections"))
    for r in loaded.routes:
        src, dst = project.node(r.src_node).port(r.src_port), project.node(r.dst_node).port(r.dst_port)
        c = ET.SubElement(connections, _q("ssd", "Connection"), startElement=r.src_node,
                          startConnector=src.variable or src.name, endElement=r.dst_node,
                          endConnector=dst.variable or dst.name)
        if r.transform is not None:
            ET.SubElement(c, _q("ssc", "LinearTransformation"), factor=repr(r.transform[0]), offset=repr(r.transform[1]))
    cosim = project.coSimulation
    experiment = ET.SubElement(root, _q("ssd", "DefaultExperiment"), startTime=repr(cosim.startTime),
                               stopTime=repr(cosim.stopTime))
    note = ET.SubElement(ET.SubElement(experiment, _q("ssd", "Annotations")), _q("ssc", "Annotation"), type=ANNOTATION)
    ET.SubElement(note, _q("hycosim", "coSimulation"), stepSize=repr(cosim.stepSize))
    make_folder(out.parent)
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr(SSD, ET.tostring(root, encoding="utf-8", xml_declaration=True))
        for source, path in files.items():
            z.write(path, source)
    return out


def _ssv_type(value: Any) -> str:
    if type(value) is bool:
        return "Boolean"
    if type(value) is int:
        return "Integer"
    if type(value) is float:
        return "Real"
    if type(value) is str:
        return "String"
    raise SspError(f"a parameter value {value!r} that SSP cannot hold (numbers, Booleans and strings)")


# Beside a package, the parts of a project SSP has no word for (serverIP, events, asynchronous
# nodes, coSimulation keys): `run` and `validate` of system.ssp read system.hycosim.json.
SSP_SIDE_SUFFIX = ".hycosim.json"


def import_package(package: Path, project_file: Path, side: Path | None = None, step: float | None = None,
                   stop: float | None = None) -> Path:
    """Import the SSP package into ``project_file`` (its FMUs in a folder beside it), with the
    side file beside the package (or ``side``); SspError saying what is wrong with any of them."""
    import json

    from hycosim.core import json_text

    beside = package.with_name(package.stem + SSP_SIDE_SUFFIX)
    side = side or (beside if beside.is_file() else None)
    try:
        extra = json_text.loads(side.read_bytes()) if side is not None else None
        if extra is not None and type(extra) is not dict:
            raise ValueError("it holds no JSON object")
    except (OSError, ValueError, RecursionError) as exc:
        raise SspError(f"{side}: cannot read the side file ({exc})") from None
    doc = project_from_ssp(package, project_file.parent / f"{project_file.stem}-fmus", side=extra, step=step,
                           stop=stop)
    try:
        project_file.write_text(json.dumps(doc, indent=1))
    except OSError as exc:
        raise SspError(f"{project_file}: cannot write ({exc.strerror or exc})") from None
    return project_file


def imported_project(package: Path, step: float | None = None, stop: float | None = None) -> Path:
    """The project ``hycosim run`` and ``validate`` use for a package: imported into a hidden
    folder beside it (remade each time); SspError saying what went wrong."""
    folder = package.parent / f".{package.name}.d"
    try:
        folder.mkdir(exist_ok=True)
    except OSError as exc:
        raise SspError(f"{folder}: cannot make the folder the package is imported into "
                       f"({exc.strerror or exc}); import it elsewhere with: hycosim import {package} "
                       "-o DIR/project.json") from None
    return import_package(package, folder / "project.json", step=step, stop=stop)
