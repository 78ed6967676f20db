"""OSP system structures (OspSystemStructure.xml, libcosim's format): imported into a project,
run and validated straight from the XML or its folder; anything hycosim cannot take named with
its place in the XML, exit 2, before anything starts; the reader total over drawn and hostile
XML. Against libcosim: benchmarks/crosscheck.py's ``osp`` system."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from xml.sax.saxutils import quoteattr

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hycosim.core.config import parse_project
from hycosim.fmi.osp import MAX_BYTES, OspError, project_from_osp
from tests.helpers import hycosim

NS = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"


@pytest.fixture(scope="module")
def system(tmp_path_factory) -> Path:
    if shutil.which("gcc") is None:
        pytest.skip("needs gcc")
    from benchmarks._small_fmus import build, osp_structure

    root = tmp_path_factory.mktemp("osp")
    return osp_structure(build(root / "fmus"), root / "system", 40, 0.01)


def test_a_structure_imports_as_a_project_and_runs_from_its_xml_or_folder(system, tmp_path):
    res = hycosim("import", str(system.parent), "-o", str(tmp_path / "p.json"))
    assert res.returncode == 0, res.stderr
    doc = json.loads((tmp_path / "p.json").read_text())
    nodes = {n["nodeName"]: n for n in doc["nodeLists"]}
    assert nodes["dahlquist"]["parameters"] == {"k": 2.0}
    assert nodes["types"]["parameters"] == {"gain": 3.0, "offset": 5, "bu": True}  # Real, Integer, Boolean
    assert nodes["ball"]["stepSize"] == 0.02 and "stepSize" not in nodes["ft"]  # a multi-rate simulator
    links = {(ln["from"], ln["to"]): (ln.get("factor"), ln.get("offset")) for ln in doc["linkLists"]}
    assert links[("dahlquist.x", "ft.u")] == (2.0, 1.0)  # the LinearTransformation
    assert links[("loopB.y", "loopA.u")] == (0.5, 1.0) and links[("loopA.y", "loopB.u")] == (None, None)
    assert links[("ball.h", "height.u")] == (None, None)  # a Sum of one signal
    assert links[("ball.falling", "types.bu")] == (None, None) and links[("ball.bounces", "types.iu")] == (None, None)
    assert doc["coSimulation"] == {"startTime": 0.0, "stepSize": 0.01, "stopTime": 0.4}
    runs = []
    for target in (tmp_path / "p.json", system, system.parent):
        out = tmp_path / f"runs-{len(runs)}"
        res = hycosim("run", str(target), "--runs-dir", str(out), "--no-progress", "--in-process")
        assert res.returncode == 0, res.stderr
        runs.append((next(out.iterdir()) / "values.csv").read_bytes())
    assert runs[0] == runs[1] == runs[2]
    res = hycosim("validate", str(system))
    assert res.returncode == 0 and "project 'system', 9 nodes" in res.stdout, res.stdout + res.stderr


def _edit(system: Path, tmp_path: Path, old: str, new: str) -> Path:
    folder = tmp_path / "edited"
    shutil.copytree(system.parent, folder, ignore=shutil.ignore_patterns(".*"))
    xml = folder / "OspSystemStructure.xml"
    text = xml.read_text()
    assert old in text
    xml.write_text(text.replace(old, new))
    return xml


@pytest.mark.parametrize("old, new, says", [
    ('<Sum name="one" inputCount="1"/>', '<Sum name="one" inputCount="2"/>',
     "Functions/Sum[3] (one): a sum of 2 signals; a hycosim link carries one output to one input"),
    ('<Variable simulator="ft" name="y"/>', '<Variable simulator="ft" name="nope"/>',
     "Connections/VariableConnection[1]/Variable[1]: Feedthrough.fmu (simulator ft) has no variable 'nope'"),
    ('<Integer value="5"/>', '<Real value="5.5"/>',
     "Simulators/Simulator[8] (types)/InitialValues/InitialValue[2]: 'offset' of Types.fmu is Integer; the value "
     "given is Real"),
    ('<Real value="0.7"/>', '<String value="bouncy"/>',
     "Simulators/Simulator[9] (ball)/InitialValues/InitialValue[1]: 'e' of Ball.fmu is Real; the value given is "
     "String"),
    ('<Boolean value="true"/>', '<Boolean value="yes"/>', "'yes' is no Boolean (true, false, 1 or 0)"),
    ('source="Ball.fmu" stepSize="0.02"', 'source="Ball.fmu" stepSize="0.015"',
     "Simulators/Simulator[9] (ball)/@stepSize: 0.015 s is no whole multiple of the base step 0.01 s"),
    ('source="Ball.fmu"', 'source="proxy-fmu://host/Ball.fmu"',
     "Simulators/Simulator[9] (ball): source 'proxy-fmu://host/Ball.fmu' is a proxy-fmu: URI"),
    ("<Algorithm>fixedStep</Algorithm>", "<Algorithm>magic</Algorithm>", "Algorithm: 'magic'"),
    ('<Signal function="twice" name="out"/>', '<Signal function="twice" name="outt"/>',
     "Functions/LinearTransformation[1] (twice): no SignalConnection to its signal 'out'"),
    (f'xmlns="{NS}"', 'xmlns="http://example.com/other"', "not OspSystemStructure in the namespace"),
    ("<BaseStepSize>0.01</BaseStepSize>", "", "BaseStepSize: missing; give --step"),
    ('<VariableConnection powerBond="bond"><Variable simulator="bondB"', '<VariableConnection><Variable simulator="bondB"',
     "the power bond 'bond' has 1 connection; a power bond is two"),
])
def test_what_hycosim_cannot_take_is_named_with_its_place_exit_2(system, tmp_path, old, new, says):
    xml = _edit(system, tmp_path, old, new)
    res = hycosim("validate", str(xml))
    assert res.returncode == 2 and says in " ".join(res.stderr.split()), res.stderr
    assert "Traceback" not in res.stderr


def test_ecco_runs_as_the_error_controlled_step_with_a_warning(system, tmp_path):
    xml = _edit(system, tmp_path, "<Algorithm>fixedStep</Algorithm>", "<Algorithm>ecco</Algorithm>")
    with pytest.raises(OspError, match=r"Simulator\[9\] \(ball\)/@stepSize: a step of its own under Algorithm ecco"):
        project_from_osp(xml, tmp_path)
    xml.write_text(xml.read_text().replace(' stepSize="0.02"', ""))
    made = project_from_osp(xml, tmp_path)
    assert made.project["coSimulation"]["stepControl"] == {"tolerance": 1e-4, "minStep": 1e-4, "maxStep": 1.0}
    assert any("not ECCO's energy-based controller" in w for w in made.warnings)


def test_hostile_xml_is_one_named_error(system, tmp_path):
    bomb = ('<?xml version="1.0"?><!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;&lol;&lol;">]>'
            f'<OspSystemStructure xmlns="{NS}" version="0.1"><Simulators>&lol2;</Simulators></OspSystemStructure>')
    external = ('<?xml version="1.0"?><!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>'
                f'<OspSystemStructure xmlns="{NS}" version="0.1"><Simulators>&e;</Simulators></OspSystemStructure>')
    for i, (text, says) in enumerate([(bomb, "has a DOCTYPE"), (external, "has a DOCTYPE"),
                                      ("<OspSystemStructure", "not well-formed XML"),
                                      (b"\xff\xfe<x/>", "not well-formed XML")]):
        xml = tmp_path / f"bad{i}.xml"
        xml.write_bytes(text if isinstance(text, bytes) else text.encode())
        with pytest.raises(OspError, match=says):
            project_from_osp(xml, tmp_path)
    huge = tmp_path / "huge.xml"
    with huge.open("wb") as f:
        f.truncate(MAX_BYTES + 1)
    with pytest.raises(OspError, match="an OSP system structure is at most"):
        project_from_osp(huge, tmp_path)
    res = hycosim("validate", str(tmp_path / "bad0.xml"))
    assert res.returncode == 2 and "has a DOCTYPE" in res.stderr and "Traceback" not in res.stderr


# --- the reader over drawn structures ---------------------------------------------------

_NAMES = st.sampled_from(["dahlquist", "ft", "types", "ball", "9bad", "", "a b", "x" * 300])
_VARS = st.sampled_from(["x", "u", "y", "k", "gain", "offset", "bu", "iu", "ru", "h", "falling", "nope", ""])
_TEXT = st.sampled_from(["0.01", "0", "-1", "nan", "inf", "1e308", "abc", "", "2", "0.02", "true", "5"])
# The right ones, drawn more often: most structures drawn are ones hycosim takes, so that what
# the reader makes of them meets the project file's checks.
_MODELS = {"dahlquist": "Dahlquist", "ft": "Feedthrough", "types": "Types", "ball": "Ball"}
_INITIAL = {"dahlquist": [("k", "Real", "2.0")], "ft": [("u", "Real", "1.5")],
            "types": [("gain", "Real", "3"), ("offset", "Integer", "5"), ("bu", "Boolean", "true")],
            "ball": [("e", "Real", "0.7")]}
_OUTPUTS = [("dahlquist", "x"), ("ft", "y"), ("types", "ry"), ("types", "iy"), ("ball", "h"), ("ball", "bounces"),
            ("ball", "falling")]
_INPUTS = [("ft", "u"), ("types", "ru"), ("types", "iu"), ("types", "bu")]


def _pick(draw, right: list, wrong: st.SearchStrategy, valid: bool):
    return draw(st.sampled_from(right)) if valid or draw(st.integers(0, 3)) else draw(wrong)


@st.composite
def structures(draw, fmus: dict[str, Path]) -> str:
    """An OspSystemStructure.xml of the schema's elements in any mix: mostly right (simulators
    of the small FMUs, their variables, valid numbers), with wrong names, sources, numbers,
    value types, functions, connections and namespaces drawn in."""
    valid = draw(st.booleans())
    text = (lambda right: _pick(draw, right, _TEXT, valid))
    parts = [f"<StartTime>{text(['0', '0.0'])}</StartTime>", f"<EndTime>{text(['0.05', '0.1'])}</EndTime>",
             f"<BaseStepSize>{text(['0.01'])}</BaseStepSize>",
             f"<Algorithm>{_pick(draw, ['fixedStep', 'ecco'], _TEXT, valid)}</Algorithm>"]
    parts = [part for part in parts if valid or draw(st.integers(0, 4))]
    names = draw(st.lists(st.sampled_from(list(_MODELS)), min_size=1, max_size=4, unique=True)
                 .filter(lambda drawn: valid or len(drawn) > 0))
    sims = []
    for name in names:
        if not valid and not draw(st.integers(0, 5)):
            name = draw(_NAMES)
        source = str(fmus[_MODELS[name]]) if name in _MODELS else "missing.fmu"
        if not valid and not draw(st.integers(0, 5)):
            source = draw(st.sampled_from(["missing.fmu", "proxy-fmu://h/x.fmu", "", *map(str, fmus.values())]))
        step = f' stepSize="{text(["0.01", "0.02", "0.03"])}"' if draw(st.booleans()) else ""
        values = ""
        for var, kind, value in draw(st.lists(st.sampled_from(_INITIAL.get(name, [("x", "Real", "1")])),
                                              max_size=3, unique=True)):
            if not valid and not draw(st.integers(0, 3)):
                var, kind, value = (draw(_VARS), draw(st.sampled_from(["Real", "Integer", "Boolean", "String", "Enum"])),
                                    draw(_TEXT))
            values += f"<InitialValue variable={quoteattr(var)}><{kind} value={quoteattr(value)}/></InitialValue>"
        sims.append(f"<Simulator name={quoteattr(name)} source={quoteattr(source)}{step}>"
                    f"<InitialValues>{values}</InitialValues></Simulator>")
    parts.append("<Simulators>" + "".join(sims) + "</Simulators>")
    functions, connections = [], []
    # Connections between the simulators drawn (others are drawn among the wrong ones).
    outputs = [end for end in _OUTPUTS if end[0] in names] or _OUTPUTS
    inputs = [end for end in _INPUTS if end[0] in names] or _INPUTS
    for i in range(draw(st.integers(0, 2))):
        kind = _pick(draw, ["LinearTransformation", "Sum"], st.sampled_from(["VectorSum", "Odd", "Sum"]), valid)
        count = _pick(draw, ["1"], _TEXT, valid)
        functions.append(f'<{kind} name="f{i}" factor="{text(["2", "0.5"])}" offset="{text(["1", "0"])}" '
                         f'inputCount="{count}" dimension="2"/>')
        src, dst = draw(st.sampled_from(outputs)), draw(st.sampled_from(inputs))
        signal = "in" if kind == "LinearTransformation" else "in[0]"
        for (sim, var), sig in ((src, signal), (dst, "out")):
            connections.append(f"<SignalConnection><Variable simulator={quoteattr(sim)} name={quoteattr(var)}/>"
                               f"<Signal function=\"f{i}\" name={quoteattr(_pick(draw, [sig], st.just('x'), valid))}/>"
                               "</SignalConnection>")
    parts.append("<Functions>" + "".join(functions) + "</Functions>")
    for _ in range(draw(st.integers(0, 4))):
        kind = _pick(draw, ["VariableConnection"], st.sampled_from(["VariableGroupConnection", "Other"]), valid)
        ends = [draw(st.sampled_from(outputs)), draw(st.sampled_from(inputs))]
        if not valid and not draw(st.integers(0, 3)):
            ends = [(draw(_NAMES), draw(_VARS)) for _ in range(draw(st.integers(0, 3)))]
        inner = "".join(f"<Variable simulator={quoteattr(sim)} name={quoteattr(var)}/>"
                        for sim, var in draw(st.permutations(ends)))
        connections.append(f"<{kind}>{inner}</{kind}>")
    parts.append("<Connections>" + "".join(connections) + "</Connections>")
    ns = _pick(draw, [NS], st.just("http://example.com/x"), valid)
    return f'<?xml version="1.0"?><OspSystemStructure xmlns="{ns}" version="0.1">{"".join(parts)}</OspSystemStructure>'


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    if shutil.which("gcc") is None:
        pytest.skip("needs gcc")
    from benchmarks._small_fmus import build

    built = build(tmp_path_factory.mktemp("fmus"))
    return {k: built[k] for k in ("Dahlquist", "Feedthrough", "Types", "Ball")}


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_the_reader_gives_a_project_the_loader_takes_or_one_named_error(fmus, tmp_path, data):
    xml = tmp_path / "OspSystemStructure.xml"
    xml.write_text(data.draw(structures(fmus)))
    try:
        made = project_from_osp(xml, tmp_path)
    except OspError as exc:
        assert str(exc).startswith(f"{xml}: ")
        return
    parse_project(made.project, "imported")  # what the reader makes, the project file's checks take
