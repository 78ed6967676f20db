"""OSP system structures (``OspSystemStructure.xml``, libcosim's format) as hycosim projects.

A simulator becomes an FMU node (its FMU where ``source`` says, relative to the XML), with a
port for each of the FMU's outputs and for each input a connection feeds, and its
``InitialValues`` as parameters (set before the FMU is initialised, as libcosim sets them); a
simulator's ``stepSize`` makes it a multi-rate node. ``VariableConnection`` becomes a link
from the output to the input; a power bond is its two connections, two links. A
``LinearTransformation`` between two variables (its ``in`` and ``out`` signals) becomes a link
with its factor and offset, a ``Sum`` of one input a plain link. ``BaseStepSize``,
``StartTime`` and ``EndTime`` become the macro step, start and stop time; ``fixedStep`` is
Jacobi, and ``ecco`` the error-controlled step, with a warning: it is not ECCO's energy-based
controller.

What hycosim cannot take (a sum of several signals, a vector sum, variable and signal groups,
a simulator from a URI that is no file, a connection to a variable its FMU lacks) is named with
its place in the XML before anything starts: :class:`OspError`. The XML is read without a DTD,
entities or network, and no larger than MAX_BYTES.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlparse

from hycosim.core.schema import ASSIGNABLE, PortType

NAMESPACE = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
STRUCTURE_FILE = "OspSystemStructure.xml"
MAX_BYTES = 16 * 1024 * 1024  # a system structure is a few kilobytes; far more is no structure
_INT32 = (-(2**31), 2**31 - 1)


class OspError(RuntimeError):
    """An OSP system structure hycosim cannot take; the message names the file and the place."""


@dataclass
class OspProject:
    """The project made of a structure, and what the reader warns of."""

    project: dict[str, Any]
    warnings: list[str] = field(default_factory=list)


def structure_file(path: Path) -> Path:
    """The structure's XML: ``path`` itself, or the OspSystemStructure.xml in the folder ``path``."""
    return path / STRUCTURE_FILE if path.is_dir() else path


def is_structure(path: Path) -> bool:
    """Whether ``path`` names an OSP system structure (an .xml file, or a folder holding one)."""
    return path.suffix.lower() == ".xml" or (path.is_dir() and (path / STRUCTURE_FILE).is_file())


def _q(tag: str) -> str:
    return f"{{{NAMESPACE}}}{tag}"


def _parse(xml: Path) -> Any:
    """The XML's root element; OspError for a file that is not one safe, well-formed structure."""
    from lxml import etree

    try:
        size = xml.stat().st_size
        if size > MAX_BYTES:
            raise OspError(f"{xml}: {size} bytes; an OSP system structure is at most {MAX_BYTES} bytes here")
        data = xml.read_bytes()
    except OSError as exc:
        raise OspError(f"{xml}: cannot read ({exc.strerror or exc})") from None
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False,
                             remove_comments=True)
    try:
        tree = etree.fromstring(data, parser).getroottree()
    except etree.XMLSyntaxError as exc:
        raise OspError(f"{xml}: not well-formed XML ({exc})") from None
    if tree.docinfo.doctype:
        raise OspError(f"{xml}: has a DOCTYPE; an OSP system structure has none (entities are not read)")
    root = tree.getroot()
    if root.tag != _q("OspSystemStructure"):
        raise OspError(f"{xml}: the root element is {root.tag!r}, not OspSystemStructure in the namespace "
                       f"{NAMESPACE}")
    return root


def _number(text: str | None, where: str, problems: list[str], positive: bool = False) -> float | None:
    if text is None:
        return None
    try:
        value = float(text.strip())
    except ValueError:
        problems.append(f"{where}: {text!r} is no number")
        return None
    if not math.isfinite(value) or (positive and value <= 0):
        problems.append(f"{where}: {text!r} is not a {'positive ' if positive else ''}finite number")
        return None
    return value


def _child_text(root: Any, tag: str, problems: list[str], positive: bool = False) -> float | None:
    found = root.find(_q(tag))
    return None if found is None else _number(found.text, tag, problems, positive)


def _value(element: Any, where: str, problems: list[str]) -> tuple[str, Any] | None:
    """An InitialValue's (type, value)."""
    kind = element.tag.replace(f"{{{NAMESPACE}}}", "")
    text = element.get("value")
    if text is None:
        problems.append(f"{where}: no value attribute")
        return None
    if kind == "Real":
        value = _number(text, where, problems)
        return None if value is None else ("Real", value)
    if kind == "Integer":
        try:
            number = int(text.strip())
        except ValueError:
            problems.append(f"{where}: {text!r} is no whole number")
            return None
        if not _INT32[0] <= number <= _INT32[1]:
            problems.append(f"{where}: {number} does not fit an FMI Integer (32 bits)")
            return None
        return "Integer", number
    if kind == "Boolean":
        word = text.strip().lower()
        if word not in ("true", "false", "1", "0"):
            problems.append(f"{where}: {text!r} is no Boolean (true, false, 1 or 0)")
            return None
        return "Boolean", word in ("true", "1")
    if kind == "String":
        return "String", text
    problems.append(f"{where}: a {kind} value; an initial value is Real, Integer, Boolean or String")
    return None


# FMI variable types → the OSP value type that sets them.
_VALUE_TYPE = {"Real": "Real", "Float64": "Real", "Float32": "Real", "Boolean": "Boolean", "String": "String"}
# FMI variable types → port types.
_PORT_TYPE = {"Real": "Real", "Float64": "Real", "Float32": "Real", "Boolean": "Boolean", "String": "String"}


def _port_type(var: Any) -> str:
    return _PORT_TYPE.get(var.type, "Binary" if var.type == "Binary" else "Integer")


def _port_name(variable: str, taken: set[str]) -> str:
    """A port name for an FMU variable: the variable's own where it is an identifier."""
    name = variable if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", variable) else \
        (re.sub(r"\W", "_", variable).lstrip("0123456789") or "port")
    base, k = name, 2
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    taken.add(name)
    return name


@dataclass
class _Simulator:
    name: str
    where: str
    fmu: Path
    variables: dict[str, Any]  # fmpy ScalarVariables by name
    step: float | None
    initial: dict[str, Any]
    fed: list[str] = field(default_factory=list)  # inputs a connection feeds


def _simulators(root: Any, base: Path, problems: list[str]) -> dict[str, _Simulator]:
    from hycosim.fmi.loader import FmuError, describe

    out: dict[str, _Simulator] = {}
    holder = root.find(_q("Simulators"))
    if holder is None:
        problems.append("Simulators: missing")
        return out
    for i, element in enumerate(holder.findall(_q("Simulator")), start=1):
        where = f"Simulators/Simulator[{i}]"
        name, source = element.get("name"), element.get("source")
        if not name or source is None:
            problems.append(f"{where}: needs the attributes name and source")
            continue
        where = f"{where} ({name})"
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_\-]*", name) or len(name) > 200:
            problems.append(f"{where}: the name {name!r} cannot name a hycosim node (a letter, then letters, "
                            "digits, '_' or '-')")
            continue
        if name in out:
            problems.append(f"{where}: a second simulator named {name!r}")
            continue
        uri = urlparse(source)
        if uri.scheme not in ("", "file"):
            problems.append(f"{where}: source {source!r} is a {uri.scheme}: URI; hycosim runs FMU files")
            continue
        fmu = (base / unquote(uri.path if uri.scheme else source)).resolve()
        try:
            md = describe(fmu)
        except FmuError as exc:
            problems.append(f"{where}: {exc}")
            continue
        step = _number(element.get("stepSize"), f"{where}/@stepSize", problems, positive=True)
        variables = {v.name: v for v in md.modelVariables}
        initial: dict[str, Any] = {}
        values = element.find(_q("InitialValues"))
        for j, iv in enumerate(values.findall(_q("InitialValue")) if values is not None else [], start=1):
            at = f"{where}/InitialValues/InitialValue[{j}]"
            variable = iv.get("variable")
            typed = [child for child in iv if isinstance(child.tag, str)]
            if not variable or len(typed) != 1:
                problems.append(f"{at}: needs a variable attribute and one value element")
                continue
            got = _value(typed[0], f"{at} ({variable})", problems)
            if got is None:
                continue
            var = variables.get(variable)
            if var is None:
                problems.append(f"{at}: {fmu.name} has no variable {variable!r}")
                continue
            wanted = _VALUE_TYPE.get(var.type, "Integer")
            if got[0] != wanted:
                problems.append(f"{at}: {variable!r} of {fmu.name} is {var.type}; the value given is {got[0]}")
                continue
            initial[variable] = got[1]
        out[name] = _Simulator(name, where, fmu, variables, step, initial)
    return out


def _endpoint(element: Any, where: str, sims: dict[str, _Simulator], problems: list[str]) -> tuple[str, str] | None:
    """A Variable endpoint: (simulator, variable), both there."""
    sim, name = element.get("simulator"), element.get("name")
    if not sim or not name:
        problems.append(f"{where}: needs the attributes simulator and name")
        return None
    if sim not in sims:
        problems.append(f"{where}: no simulator named {sim!r}")
        return None
    if name not in sims[sim].variables:
        problems.append(f"{where}: {sims[sim].fmu.name} (simulator {sim}) has no variable {name!r}")
        return None
    return sim, name


def _causality(sims: dict[str, _Simulator], end: tuple[str, str]) -> str:
    return sims[end[0]].variables[end[1]].causality or "local"


_SOURCES = ("output", "calculatedParameter")


def _functions(root: Any, problems: list[str]) -> tuple[dict[str, tuple[str, str, dict[str, float]]], set[str]]:
    """The Functions hycosim can express, by name: (kind, XML place, factor and offset); and the
    names of every function the structure declares."""
    out: dict[str, tuple[str, str, dict[str, float]]] = {}
    declared: set[str] = set()
    holder = root.find(_q("Functions"))
    if holder is None:
        return out, declared
    for i, element in enumerate((e for e in holder if isinstance(e.tag, str)), start=1):
        kind = element.tag.replace(f"{{{NAMESPACE}}}", "")
        name = element.get("name")
        where = f"Functions/{kind}[{i}]" + (f" ({name})" if name else "")
        if not name:
            problems.append(f"{where}: needs a name")
            continue
        declared.add(name)
        if kind == "LinearTransformation":
            factor = _number(element.get("factor", "1"), f"{where}/@factor", problems)
            offset = _number(element.get("offset", "0"), f"{where}/@offset", problems)
            if factor is not None and offset is not None:
                out[name] = (kind, where, {"factor": factor, "offset": offset})
        elif kind == "Sum":
            count = element.get("inputCount")
            if count != "1":
                problems.append(f"{where}: a sum of {count} signals; a hycosim link carries one output to one "
                                "input and sums nothing (a Sum of one input is taken as a plain link)")
                continue
            out[name] = (kind, where, {"factor": 1.0, "offset": 0.0})
        elif kind == "VectorSum":
            problems.append(f"{where}: a VectorSum needs OSP variable groups, which hycosim does not read; "
                            "connect the variables one by one")
        else:
            problems.append(f"{where}: an OSP function hycosim does not know")
    return out, declared


_Link = tuple[tuple[str, str], tuple[str, str], dict[str, float], str]


def _links(root: Any, sims: dict[str, _Simulator], problems: list[str]) -> list[_Link]:
    """(source, destination, transformation, XML place) for each connection."""
    links = []
    holder = root.find(_q("Connections"))
    if holder is None:
        return links
    functions, declared = _functions(root, problems)
    signals: dict[tuple[str, str], tuple[tuple[str, str], str]] = {}
    counts: dict[str, int] = {}
    for element in (e for e in holder if isinstance(e.tag, str)):
        kind = element.tag.replace(f"{{{NAMESPACE}}}", "")
        counts[kind] = counts.get(kind, 0) + 1
        where = f"Connections/{kind}[{counts[kind]}]"
        if kind == "VariableConnection":
            ends = element.findall(_q("Variable"))
            if len(ends) != 2:
                problems.append(f"{where}: needs two Variable elements")
                continue
            a, b = (_endpoint(e, f"{where}/Variable[{j}]", sims, problems) for j, e in enumerate(ends, start=1))
            if a is None or b is None:
                continue
            if _causality(sims, a) in _SOURCES:
                links.append((a, b, {}, where))
            elif _causality(sims, b) in _SOURCES:
                links.append((b, a, {}, where))
            else:
                problems.append(f"{where}: neither {a[0]}.{a[1]} nor {b[0]}.{b[1]} is an output")
        elif kind == "SignalConnection":
            variable, signal = element.find(_q("Variable")), element.find(_q("Signal"))
            if variable is None or signal is None:
                problems.append(f"{where}: needs a Variable and a Signal")
                continue
            end = _endpoint(variable, f"{where}/Variable", sims, problems)
            function, name = signal.get("function"), signal.get("name")
            if end is None:
                continue
            if function not in functions:
                if function not in declared:  # a declared one hycosim cannot take is named above
                    problems.append(f"{where}/Signal: no function named {function!r}")
                continue
            signals[(function, name or "")] = (end, where)
        else:
            problems.append(f"{where}: hycosim does not read OSP variable or signal groups; connect the variables "
                            "one by one")
    for name, (kind, where, transform) in functions.items():
        ins = ("in",) if kind == "LinearTransformation" else ("in[0]",)
        got_in, got_out = signals.get((name, ins[0])), signals.get((name, "out"))
        if got_in is None or got_out is None:
            missing = ins[0] if got_in is None else "out"
            problems.append(f"{where}: no SignalConnection to its signal {missing!r}")
            continue
        (src, src_where), (dst, dst_where) = got_in, got_out
        kinds = [(end, w) for end, w in ((src, src_where), (dst, dst_where))
                 if _VALUE_TYPE.get(sims[end[0]].variables[end[1]].type) != "Real"]
        if kinds:
            (end, w), = kinds[:1]
            problems.append(f"{w}: {end[0]}.{end[1]} is {sims[end[0]].variables[end[1]].type}; an OSP function "
                            "takes and gives Real signals")
            continue
        if _causality(sims, src) not in _SOURCES:
            problems.append(f"{src_where}: {src[0]}.{src[1]} feeds {name}:{ins[0]} but is no output")
            continue
        if _causality(sims, dst) != "input":
            problems.append(f"{dst_where}: {name}:out feeds {dst[0]}.{dst[1]}, which is no input")
            continue
        links.append((src, dst, transform, functions[name][1]))
    for (fn, signal), (_, where) in signals.items():
        expected = ("in", "out") if functions[fn][0] == "LinearTransformation" else ("in[0]", "out")
        if signal not in expected:
            problems.append(f"{where}/Signal: {fn} has no signal {signal!r} (it has {', '.join(expected)})")
    return links


def project_from_osp(path: Path, project_dir: Path, step: float | None = None,
                     stop: float | None = None) -> OspProject:
    """The project (a dict) for the OSP system structure at ``path`` (a file, or a folder with
    OspSystemStructure.xml), its FMUs named relative to ``project_dir``, where the project file
    goes; ``step``/``stop``: the macro step and stop time where the structure gives none.
    OspError naming the file and every place that cannot be taken."""
    xml = structure_file(path)
    root = _parse(xml)
    problems: list[str] = []
    warnings: list[str] = []
    version = root.get("version")
    if version not in ("0.1", None):
        warnings.append(f"{xml}: version {version!r}; hycosim reads version 0.1")
    base_step = _child_text(root, "BaseStepSize", problems, positive=True)
    start = _child_text(root, "StartTime", problems) or 0.0
    end = _child_text(root, "EndTime", problems)
    base_step = base_step if step is None else step
    end = end if stop is None else stop
    sims = _simulators(root, xml.parent, problems)
    links = _links(root, sims, problems)
    bonds: dict[str, int] = {}
    connections = root.find(_q("Connections"))
    for element in connections.findall(_q("VariableConnection")) if connections is not None else []:
        if element.get("powerBond") is not None:
            bonds[element.get("powerBond")] = bonds.get(element.get("powerBond"), 0) + 1
    for bond, count in bonds.items():
        if count != 2:
            problems.append(f"Connections: the power bond {bond!r} has {count} connection{'s' * (count != 1)}; a "
                            "power bond is two (effort one way, flow the other)")
    fed: dict[tuple[str, str], str] = {}
    for src, dst, _, where in links:
        if dst in fed:
            problems.append(f"{where}: {dst[0]}.{dst[1]} is fed by {fed[dst]} already; an input takes one connection")
        fed[dst] = f"{src[0]}.{src[1]}"
        src_type, dst_type = (_port_type(sims[end[0]].variables[end[1]]) for end in (src, dst))
        if sims[dst[0]].variables[dst[1]].causality != "input":
            problems.append(f"{where}: {src[0]}.{src[1]} feeds {dst[0]}.{dst[1]}, which is no input of "
                            f"{sims[dst[0]].fmu.name}")
        elif PortType(src_type) not in ASSIGNABLE[PortType(dst_type)]:
            problems.append(f"{where}: {src[0]}.{src[1]} ({src_type}) cannot feed {dst[0]}.{dst[1]} ({dst_type})")
        elif dst[1] not in sims[dst[0]].fed:
            sims[dst[0]].fed.append(dst[1])
    cosim: dict[str, Any] = {"startTime": start}
    if base_step is None:
        problems.append("BaseStepSize: missing; give --step")
    else:
        cosim["stepSize"] = base_step
        for sim in sims.values():
            ratio = None if sim.step is None else sim.step / base_step
            if ratio is not None and not (math.isfinite(ratio) and ratio < 1e9 and abs(ratio - round(ratio)) <= 1e-9
                                          and round(ratio) >= 1):
                problems.append(f"{sim.where}/@stepSize: {sim.step:g} s is no whole multiple of the base step "
                                f"{base_step:g} s")
    if end is None:
        problems.append("EndTime: missing; give --stop")
    else:
        cosim["stopTime"] = end
    algorithm = (root.findtext(_q("Algorithm")) or "fixedStep").strip()
    if algorithm == "ecco":
        ecco = root.find(_q("EccoConfiguration"))
        tolerance = _child_text(ecco, "RelativeTolerance", problems, positive=True) if ecco is not None else None
        low = _child_text(ecco, "MinimumStepSize", problems, positive=True) if ecco is not None else None
        high = _child_text(ecco, "MaximumStepSize", problems, positive=True) if ecco is not None else None
        if base_step is not None:
            cosim["stepControl"] = {"tolerance": tolerance or 1e-4, "minStep": low or base_step / 100,
                                    "maxStep": high or base_step * 100}
        for sim in sims.values():
            if sim.step is not None and base_step is not None and sim.step != base_step:
                problems.append(f"{sim.where}/@stepSize: a step of its own under Algorithm ecco; hycosim's "
                                "error-controlled step runs every simulator at the base step")
        warnings.append(f"{xml}: Algorithm ecco runs as hycosim's error-controlled step (coSimulation.stepControl: "
                        "the held inputs' error), which is not ECCO's energy-based controller")
    elif algorithm != "fixedStep":
        problems.append(f"Algorithm: {algorithm!r}; an OSP structure names fixedStep or ecco")
    if problems:
        raise OspError(f"{xml}: " + "; ".join(problems))
    nodes = []
    ports: dict[tuple[str, str], str] = {}
    for uid, sim in enumerate(sims.values(), start=1):
        taken: set[str] = set()
        node: dict[str, Any] = {"nodeName": sim.name, "UID": uid,
                                "fmu": os.path.relpath(sim.fmu, project_dir.resolve()), "input": [], "output": []}
        for role, names in (("output", [v.name for v in sim.variables.values() if v.causality == "output"]),
                            ("input", sim.fed)):
            for variable in names:
                var = sim.variables[variable]
                if getattr(var, "dimensions", None):
                    continue  # an FMI 3 array: no OSP connection addresses one
                port = _port_name(variable, taken)
                entry: dict[str, Any] = {"name": port, "type": _port_type(var)}
                if port != variable:
                    entry["variable"] = variable
                node[role].append(entry)
                ports[(sim.name, variable)] = port
        if sim.initial:
            node["parameters"] = dict(sim.initial)
        if sim.step is not None and base_step is not None and sim.step != base_step:
            node["stepSize"] = sim.step
        nodes.append(node)
    link_list = []
    for src, dst, transform, _ in links:
        link: dict[str, Any] = {"from": f"{src[0]}.{ports[src]}", "to": f"{dst[0]}.{ports[dst]}"}
        if transform and (transform["factor"], transform["offset"]) != (1.0, 0.0):
            link.update(transform)
        link_list.append(link)
    name = re.sub(r"[^A-Za-z0-9_\-]", "_", xml.parent.name if xml.name == STRUCTURE_FILE else xml.stem) or "osp"
    return OspProject({"projectName": name, "description": f"imported from {xml.name}",
                       "serverIP": "127.0.0.1:7447", "nodeNum": len(nodes), "nodeLists": nodes,
                       "linkNum": len(link_list), "linkLists": link_list, "coSimulation": cosim}, warnings)


def import_structure(path: Path, project_file: Path, step: float | None = None,
                     stop: float | None = None) -> OspProject:
    """Write the project of the structure at ``path`` to ``project_file``; OspError saying what is wrong."""
    made = project_from_osp(path, project_file.parent, step, stop)
    try:
        project_file.write_text(json.dumps(made.project, indent=1))
    except OSError as exc:
        raise OspError(f"{project_file}: cannot write ({exc.strerror or exc})") from None
    return made


def imported_structure(path: Path, step: float | None = None, stop: float | None = None) -> tuple[Path, list[str]]:
    """The project ``hycosim run`` and ``validate`` use for a structure: written into a hidden
    folder beside it (remade each time); with the reader's warnings. OspError if it cannot be."""
    xml = structure_file(path)
    folder = xml.parent / f".{xml.name}.d"
    try:
        folder.mkdir(exist_ok=True)
    except OSError as exc:
        raise OspError(f"{folder}: cannot make the folder the structure is imported into "
                       f"({exc.strerror or exc}); import it elsewhere with: hycosim import {path} "
                       "-o DIR/project.json") from None
    made = import_structure(path, folder / "project.json", step, stop)
    return folder / "project.json", made.warnings
