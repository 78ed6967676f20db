"""SSP packages in and out: a package runs as the project it stands for, export and import
round-trip, FMPy reads what hycosim writes, and a bad package is named, nothing started."""

from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hycosim.bridge.model_fmu import build_model_fmu
from tests.helpers import REPO, free_endpoint, hycosim, read_rows, run_project, write_project

_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="chain">
  <ssd:System name="chain">
    <ssd:Elements>
      <ssd:Component name="g1" source="resources/GainModel.fmu" type="application/x-fmu-sharedlibrary">
        @IO@
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="g1">
                <ssv:Parameters>
                  <ssv:Parameter name="k"><ssv:Real value="0.5"/></ssv:Parameter>
                  <ssv:Parameter name="b"><ssv:Real value="1.0"/></ssv:Parameter>
                </ssv:Parameters>
              </ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="g2" source="resources/GainModel.fmu" type="application/x-fmu-sharedlibrary">
        @IO@
        <ssd:ParameterBindings>
          <ssd:ParameterBinding source="resources/g2.ssv"/>
        </ssd:ParameterBindings>
      </ssd:Component>
      <ssd:System name="Sub">
        <ssd:Connectors>
          <ssd:Connector name="in" kind="input"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="out" kind="output"><ssc:Real/></ssd:Connector>
        </ssd:Connectors>
        <ssd:Elements>
          <ssd:Component name="g3" source="resources/GainModel.fmu" type="application/x-fmu-sharedlibrary">
            @IO@
          </ssd:Component>
        </ssd:Elements>
        <ssd:Connections>
          <ssd:Connection startConnector="in" endElement="g3" endConnector="u"/>
          <ssd:Connection startElement="g3" startConnector="y" endConnector="out"/>
        </ssd:Connections>
      </ssd:System>
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="g1" startConnector="y" endElement="g2" endConnector="u">
        <ssc:LinearTransformation factor="2.0" offset="0.5"/>
      </ssd:Connection>
      <ssd:Connection startElement="g2" startConnector="y" endElement="Sub" endConnector="in"/>
      <ssd:Connection startElement="Sub" startConnector="out" endElement="g1" endConnector="u">
        <ssc:LinearTransformation factor="-0.25"/>
      </ssd:Connection>
    </ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0.0" stopTime="2.0"/>
</ssd:SystemStructureDescription>
""".replace("@IO@", '<ssd:Connectors><ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>'
                    '<ssd:Connector name="y" kind="output"><ssc:Real/></ssd:Connector></ssd:Connectors>')

_SSV = """<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="g2">
  <ssv:Parameters>
    <ssv:Parameter name="k"><ssv:Real value="-0.75"/></ssv:Parameter>
    <ssv:Parameter name="b"><ssv:Real value="0.2"/></ssv:Parameter>
  </ssv:Parameters>
</ssv:ParameterSet>
"""


@pytest.fixture(scope="module")
def gain(tmp_path_factory) -> Path:
    return build_model_fmu(REPO / "tests" / "models" / "gain_model.py", tmp_path_factory.mktemp("gain"))


def _package(path: Path, gain: Path, ssd: str = _SSD, ssv: str | None = _SSV, fmu: bool = True) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", ssd)
        if ssv is not None:
            z.writestr("resources/g2.ssv", ssv)
        if fmu:
            z.write(gain, "resources/GainModel.fmu")
    return path


def _by_hand(tmp_path: Path, gain: Path) -> Path:
    """The project the package stands for, written as a user would."""
    def node(name: str, uid: int, **params) -> dict:
        return {"nodeName": name, "UID": uid, "fmu": str(gain), "input": ["u"], "output": ["y"],
                **({"parameters": params} if params else {})}
    return write_project(tmp_path / "hand.json", [node("g1", 1, k=0.5, b=1.0), node("g2", 2, k=-0.75, b=0.2),
                                                  node("Sub_g3", 3)],
                         [{"from": "g1.y", "to": "g2.u", "factor": 2.0, "offset": 0.5},
                          {"from": "g2.y", "to": "Sub_g3.u"}, {"from": "Sub_g3.y", "to": "g1.u", "factor": -0.25}],
                         cosim={"stepSize": 0.1, "stopTime": 2.0}, name="chain")


def test_a_package_runs_to_the_values_of_the_project_it_stands_for(tmp_path, gain):
    package = _package(tmp_path / "chain.ssp", gain)
    # SSP 1.0 has no macro step: the side file beside the package gives it (and the server's address).
    (tmp_path / "chain.hycosim.json").write_text(json.dumps({"serverIP": free_endpoint(),
                                                             "coSimulation": {"stepSize": 0.1}}))
    assert hycosim("validate", str(package)).returncode == 0
    from_ssp = run_project(package, tmp_path / "runs-ssp")
    by_hand = run_project(_by_hand(tmp_path, gain), tmp_path / "runs-hand")
    values = (from_ssp / "values.csv").read_text()
    assert values == (by_hand / "values.csv").read_text()
    header, first, second = values.splitlines()[:3]
    assert header.split(",")[3:6] == ["g1.y", "g2.y", "Sub_g3.y"]
    # y = k·u + b at each step, on inputs transformed on the way: g2.u = 2·g1.y + 0.5.
    row = dict(zip(header.split(","), second.split(",")))
    assert float(row["g2.u"]) == pytest.approx(2 * float(row["g1.y"]) + 0.5)
    assert float(row["g1.u"]) == pytest.approx(-0.25 * float(row["Sub_g3.y"]))


def test_run_and_validate_take_the_step_a_package_without_one_needs(tmp_path, gain):
    """A package from another tool has no macro step (SSP 1.0 has none): run and validate take
    --step (and --stop) as import does, instead of asking for a side file; a project file,
    which says its own, refuses them by name."""
    package = _package(tmp_path / "chain.ssp", gain)
    res = hycosim("validate", str(package))
    assert res.returncode == 2 and "give --step" in res.stderr
    res = hycosim("validate", str(package), "--step", "0.1")
    assert res.returncode == 0, res.stderr
    run = tmp_path / "runs"
    res = hycosim("run", str(package), "--step", "0.1", "--stop", "0.5", "--runs-dir", str(run), "--no-progress")
    assert res.returncode == 0, res.stderr
    rows = read_rows(next(run.iterdir()))
    assert [float(r["t"]) for r in rows] == pytest.approx([0.1 * i for i in range(6)])
    cfg = tmp_path / ".chain.ssp.d" / "project.json"
    res = hycosim("validate", str(cfg), "--step", "0.1")
    assert res.returncode == 2 and "--step and --stop are for an SSP package" in res.stderr


def test_import_export_round_trip_and_fmpy_reads_the_package(tmp_path, gain):
    package = _package(tmp_path / "chain.ssp", gain)
    res = hycosim("import", str(package), "-o", str(tmp_path / "p" / "project.json"), "--step", "0.1")
    assert res.returncode == 0, res.stderr
    imported = json.loads((tmp_path / "p" / "project.json").read_text())
    assert [n["nodeName"] for n in imported["nodeLists"]] == ["g1", "g2", "Sub_g3"]
    assert imported["nodeLists"][1]["parameters"] == {"k": -0.75, "b": 0.2}
    assert imported["coSimulation"] == {"startTime": 0.0, "stopTime": 2.0, "stepSize": 0.1}
    assert (tmp_path / "p" / "project-fmus" / "GainModel.fmu").is_file()
    res = hycosim("export", str(tmp_path / "p" / "project.json"), "-o", str(tmp_path / "out.ssp"))
    assert res.returncode == 0, res.stderr
    res = hycosim("import", str(tmp_path / "out.ssp"), "-o", str(tmp_path / "q" / "project.json"))
    assert res.returncode == 0, res.stderr  # the macro step came back from the package's annotation
    again = json.loads((tmp_path / "q" / "project.json").read_text())
    for doc in (imported, again):
        doc.pop("description")
    assert again == imported
    # FMPy's own SSP reader and simulator take the package hycosim wrote.
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import read_ssd

    ssd = read_ssd(str(tmp_path / "out.ssp"))
    assert [e.name for e in ssd.system.elements] == ["g1", "g2", "Sub_g3"]
    result = simulate_ssp(str(tmp_path / "out.ssp"), stop_time=0.5, step_size=0.1)
    assert len(result) >= 5
    # A project SSP cannot hold is refused, naming what.
    cfg = write_project(tmp_path / "ev.json", [{"nodeName": "g", "UID": 1, "model": "gain", "input": ["u"],
                                                "output": ["y"]}])
    res = hycosim("export", str(cfg), "-o", str(tmp_path / "ev.ssp"))
    assert res.returncode == 2 and "nodeLists[0] (g): not an FMU node" in res.stderr
    assert not (tmp_path / "ev.ssp").exists()


@pytest.mark.parametrize("case", ["damaged", "schema", "missing fmu", "unknown connector", "mapping transformation",
                                  "units", "no step"])
def test_a_bad_package_is_named_with_its_path_and_nothing_starts(tmp_path, gain, case):
    ssd, fmu, expected = _SSD, True, ""
    if case == "schema":
        ssd = _SSD.replace('name="g1" source', 'nome="g1" source')
        expected = "SystemStructure.ssd does not validate against the SSP schema"
    elif case == "missing fmu":
        fmu = False
        expected = "System[chain]/Elements/Component[g1]: its FMU 'resources/GainModel.fmu' is not in the package"
    elif case == "unknown connector":
        ssd = _SSD.replace('endElement="g2" endConnector="u"', 'endElement="g2" endConnector="w"')
        expected = "Connection[g1.y → g2.w]: g2 has no connector 'w'"
    elif case == "mapping transformation":
        ssd = _SSD.replace('<ssc:LinearTransformation factor="-0.25"/>',
                           '<ssc:BooleanMappingTransformation><ssc:MapEntry source="true" target="false"/>'
                           '</ssc:BooleanMappingTransformation>')
        expected = "Connection[Sub.out → g1.u]: BooleanMappingTransformation"
    elif case == "units":
        ssd = _SSD.replace('<ssd:Connector name="y" kind="output"><ssc:Real/>',
                           '<ssd:Connector name="y" kind="output"><ssc:Real unit="mm"/>', 1)
        ssd = ssd.replace('<ssd:Connector name="u" kind="input"><ssc:Real/>',
                          '<ssd:Connector name="u" kind="input"><ssc:Real unit="m"/>')
        expected = "connection g1.y → g2.u: a unit conversion from mm to m"
    elif case == "no step":
        expected = "no stepSize: the package has no macro step (SSP 1.0 has none); give --step"
    package = tmp_path / "bad.ssp"
    if case == "damaged":
        package.write_bytes(b"PK\x03\x04 not really a zip")
        expected = f"{package}: not an SSP package"
    else:
        _package(package, gain, ssd=ssd, fmu=fmu)
    if case != "no step":
        (tmp_path / "bad.hycosim.json").write_text(json.dumps({"coSimulation": {"stepSize": 0.1}}))
    commands = [["validate", str(package)]]
    if case == "missing fmu":  # the three commands read a package the same way: each says so once
        commands += [["run", str(package), "--runs-dir", str(tmp_path / "runs")],
                     ["import", str(package), "-o", str(tmp_path / "p.json")]]
    for command in commands:
        res = hycosim(*command)
        assert res.returncode == 2, (command, res.stderr)
        assert expected in res.stderr.replace("\n", " "), (command, res.stderr)
    assert not (tmp_path / "runs").exists() and not (tmp_path / "p.json").exists()
    assert not (tmp_path / "p-fmus").exists()


_ATTRIBUTE = re.compile(r'(\w+)="([^"]*)"')


@st.composite
def _mutated_ssd(draw) -> str:
    """The good SSD with a few of its attribute values replaced (by other names in it, numbers,
    junk) or its lines dropped: packages a hand or another tool may write."""
    text = _SSD
    for _ in range(draw(st.integers(1, 3))):
        if draw(st.booleans()):
            spots = list(_ATTRIBUTE.finditer(text))
            spot = draw(st.sampled_from(spots))
            value = draw(st.one_of(st.sampled_from(["g1", "g2", "Sub", "u", "y", "in", "out", "nan", "-1", "1e308",
                                                    "resources/g2.ssv", "resources/none.fmu", "input", "output",
                                                    "parameter", ""]),
                                   st.text(alphabet=st.characters(blacklist_characters='"<>&', blacklist_categories=("Cs",)),
                                           max_size=6)))
            text = text[:spot.start(2)] + value + text[spot.end(2):]
        else:
            lines = text.splitlines()
            i = draw(st.integers(2, len(lines) - 3))
            text = "\n".join(lines[:i] + lines[i + 1:])
    return text


@settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
          deadline=None)
@given(ssd=_mutated_ssd())
def test_any_package_is_read_whole_or_refused_by_name(tmp_path_factory, gain, ssd):
    from hycosim.fmi.ssp import SspError, project_from_ssp

    tmp = tmp_path_factory.mktemp("fuzz")
    package = _package(tmp / "m.ssp", gain, ssd=ssd)
    try:
        doc = project_from_ssp(package, tmp / "fmus", step=0.1)
    except SspError as exc:
        assert str(package) in str(exc)
        return
    # What is read is a project hycosim loads (or names what is wrong with it, as any file).
    from hycosim.core.config import ConfigError, parse_project

    try:
        parse_project(doc)
    except ConfigError as exc:
        assert exc.issues


def test_a_linear_transformation_goes_only_into_real_inputs():
    from hycosim.core.config import ConfigError, parse_project

    doc = {"nodeNum": 2, "nodeLists": [
        {"nodeName": "a", "UID": 1, "model": "ramp", "output": ["y", {"name": "c", "type": "Integer"}]},
        {"nodeName": "b", "UID": 2, "model": "gain", "input": ["u", {"name": "n", "type": "Integer"}],
         "output": ["y"]}],
        "linkNum": 2, "linkLists": [{"from": "a.y", "to": "b.u", "factor": 2.0},
                                    {"from": "a.c", "to": "b.n", "offset": 1.0}]}
    with pytest.raises(ConfigError) as info:
        parse_project(doc)
    assert [i.render() for i in info.value.issues] == [
        "linkLists[1].offset: a linear transformation into Integer input b.n (hint: factor and offset apply to links "
        "into Real inputs)"]


def test_two_fmus_of_one_name_in_different_folders_stay_two(tmp_path, gain):
    other = build_model_fmu(REPO / "tests" / "models" / "gain_model3.py", tmp_path / "fmi3", fmi_version="3.0")
    ssd = _SSD.replace('name="g2" source="resources/GainModel.fmu"', 'name="g2" source="resources/v3/GainModel.fmu"')
    package = _package(tmp_path / "two.ssp", gain, ssd=ssd)
    with zipfile.ZipFile(package, "a") as z:
        z.write(other, "resources/v3/GainModel.fmu")
    from hycosim.fmi.ssp import project_from_ssp

    doc = project_from_ssp(package, tmp_path / "fmus", step=0.1)
    fmus = {n["nodeName"]: n["fmu"] for n in doc["nodeLists"]}
    assert fmus["g1"] == fmus["Sub_g3"] == "fmus/GainModel.fmu" and fmus["g2"] == "fmus/resources_v3_GainModel.fmu"
    assert (tmp_path / fmus["g2"]).read_bytes() == other.read_bytes()
    assert (tmp_path / fmus["g1"]).read_bytes() == gain.read_bytes()


@pytest.mark.parametrize("third", ["resources_v3_GainModel.fmu", ".", "Resources/V3/gainmodel.FMU"])
def test_fmu_entries_whose_file_names_would_meet_stay_apart(tmp_path, gain, third):
    """A third entry whose file name is the one the second gets (its folders joined in), in
    another letter case, or no file name at all ('.'): each node still runs its own FMU."""
    other = build_model_fmu(REPO / "tests" / "models" / "gain_model3.py", tmp_path / "fmi3", fmi_version="3.0")
    ssd = _SSD.replace('name="g2" source="resources/GainModel.fmu"', 'name="g2" source="resources/v3/GainModel.fmu"')
    ssd = ssd.replace('name="g3" source="resources/GainModel.fmu"', f'name="g3" source="{third}"')
    package = _package(tmp_path / "three.ssp", gain, ssd=ssd)
    with zipfile.ZipFile(package, "a") as z:
        z.write(other, "resources/v3/GainModel.fmu")
        z.writestr(third, gain.read_bytes())
    from hycosim.fmi.ssp import project_from_ssp

    doc = project_from_ssp(package, tmp_path / "fmus", step=0.1)
    fmus = {n["nodeName"]: tmp_path / n["fmu"] for n in doc["nodeLists"]}
    assert len({f.name.lower() for f in fmus.values()}) == 3
    assert all(f.parent == tmp_path / "fmus" and f.suffix == ".fmu" for f in fmus.values()), fmus
    assert fmus["g2"].read_bytes() == other.read_bytes()
    assert fmus["g1"].read_bytes() == fmus["Sub_g3"].read_bytes() == gain.read_bytes()


_ENTRY = st.text(alphabet="ab./\\_-A é:", max_size=12)


@given(sources=st.lists(_ENTRY, max_size=8))
def test_each_fmu_entry_of_a_package_gets_a_file_name_of_its_own(sources):
    from hycosim.fmi.ssp import fmu_file_names

    names = fmu_file_names(sources)
    assert set(names) == set(sources)
    assert len({n.lower() for n in names.values()}) == len(names)
    for name in names.values():
        assert re.fullmatch(r"[A-Za-z0-9_\-][A-Za-z0-9_.\-]*\.fmu", name), name
    if sources:  # the first entry keeps its own name where that is a plain FMU file name
        own = sources[0].rsplit("/", 1)[-1]
        if re.fullmatch(r"[A-Za-z0-9_\-][A-Za-z0-9_.\-]*\.fmu", own):
            assert names[sources[0]] == own
