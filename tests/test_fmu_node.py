"""Any FMI co-simulation FMU as a node: model FMUs built from Python classes, errors, FMI 3, rollback."""

from __future__ import annotations

import os

import json
import math
import re
import zipfile
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hycosim.core.config import load_project
from hycosim.fmi.instance import FmuInstance
from hycosim.fmi.loader import FmuError
from hycosim.fmi.fmu_open import open_fmu
from hycosim.bridge.model_fmu import ModelFmuError, build_model_fmu
from tests.helpers import REPO, column, hycosim, meta, read_rows, run_project, write_project

MODELS = REPO / "tests" / "models"
G = 9.81


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("fmus")
    return {
        "gain": build_model_fmu(MODELS / "gain_model.py", out),
        "ball": build_model_fmu(MODELS / "ball_model.py", out),
        "gain3": build_model_fmu(MODELS / "gain_model3.py", out, fmi_version="3.0"),
    }


def _gain_node(path: Path, **extra) -> dict:
    node = {"nodeName": "g", "UID": 2, "fmu": str(path), "parameters": {"k": 2.0, "b": 0.5},
            "input": ["u"], "output": ["y", {"name": "n", "type": "Integer", "variable": "count"}]}
    node.update(extra)
    return node


def test_model_fmu_runs_as_a_node_with_parameters_and_a_renamed_port(tmp_path, fmus):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        _gain_node(fmus["gain"]),
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.1, "stopTime": 1.0})
    rows = read_rows(run_project(cfg, tmp_path / "runs"))
    clock, y, n = column(rows, "clock.y"), column(rows, "g.y"), column(rows, "g.n")
    assert y[0] == 1.0 and n[0] == 0  # the FMU's own start values before any step
    for k in range(1, len(rows)):
        assert y[k] == 2.0 * clock[k - 1] + 0.5
        assert n[k] == k  # one doStep per macro step


def test_an_fmu_node_steps_on_lists_unless_a_subclass_changes_its_step(tmp_path, fmus):
    """The FMU node's listed step does what step() then outputs() do; a subclass that changes
    step() gets none, so that a run in process or over Zenoh steps it through its own."""
    from hycosim.core.schema import Port
    from hycosim.node.fmu_node import FmuNode
    from hycosim.node.runtime import node_context

    cfg = write_project(tmp_path / "p.json", [_gain_node(fmus["gain"], output=["y"])],
                        cosim={"stepSize": 0.1, "stopTime": 1.0})
    loaded = load_project(cfg)
    spec = loaded.project.node("g")

    class Clamped(FmuNode):
        def step(self, t, h, inputs):
            super().step(t, h, {"u": min(inputs["u"], 1.0)})

    nodes = []
    for cls in (FmuNode, FmuNode, Clamped):
        node = cls(spec, loaded.resolve(spec.fmu))
        node.setup(node_context(loaded, spec))
        nodes.append(node)
    try:
        listed = nodes[0].listed_step(["u"], [Port(name="y")])
        assert listed is not None and nodes[2].listed_step(["u"], [Port(name="y")]) is None
        nodes[1].step(0.0, 0.1, {"u": 3.0})
        assert listed(0.0, 0.1, (3.0,)) == [nodes[1].outputs()["y"]] == [2.0 * 3.0 + 0.5]
    finally:
        for node in nodes:
            node.teardown()


def test_fmi3_model_fmu_runs_as_a_node(tmp_path, fmus):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "fmu": str(fmus["gain3"]), "parameters": {"k": 3.0}, "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.1, "stopTime": 0.5})
    rows = read_rows(run_project(cfg, tmp_path / "runs"))
    clock, y = column(rows, "clock.y"), column(rows, "g.y")
    for k in range(1, len(rows)):
        assert math.isclose(y[k], 3.0 * clock[k - 1] + 1.0, abs_tol=1e-12)


def _instance(tmp_path: Path, fmu: Path, node: dict) -> FmuInstance:
    cfg = write_project(tmp_path / "p.json", [node])
    spec = load_project(cfg).project.node(node["nodeName"])
    return open_fmu(fmu, spec, node.get("parameters", {}))


def test_missing_variable_names_node_and_variable(tmp_path, fmus):
    with pytest.raises(FmuError, match=r"node 'g': GainModel.fmu has no variable for output 'speed' \(an FMU built for other ports"):
        _instance(tmp_path, fmus["gain"], _gain_node(fmus["gain"], output=["speed"]))


def test_type_mismatch_names_node_and_variable(tmp_path, fmus):
    with pytest.raises(FmuError, match="node 'g': input 'u' is Boolean but variable 'u' of GainModel.fmu is Real"):
        _instance(tmp_path, fmus["gain"], _gain_node(fmus["gain"], input=[{"name": "u", "type": "Boolean"}]))


def test_wrong_causality_names_the_variable(tmp_path, fmus):
    with pytest.raises(FmuError, match="variable 'y' of GainModel.fmu is an output, not an input"):
        _instance(tmp_path, fmus["gain"], _gain_node(fmus["gain"], input=[{"name": "u", "variable": "y"}]))


@pytest.mark.parametrize("name, message", [
    ("hold", "drivenVariable 'hold' is not a variable of GainModel.fmu"),
    ("y", "drivenVariable 'y' of GainModel.fmu is an output, not an input"),
    ("u", "drivenVariable 'u' is also an input port of the node"),
])
def test_a_bad_driven_variable_names_node_and_variable(tmp_path, fmus, name, message):
    with pytest.raises(FmuError, match=f"node 'g': {message}"):
        _instance(tmp_path, fmus["gain"], _gain_node(fmus["gain"], drivenVariable=name))


def test_an_event_drives_an_fmu_through_its_driven_variable(tmp_path, fmus):
    """The FMU follows its input (y = u) exactly in the steps the coordinator drives it, and
    its own law (y = 2u + 0.5) before and after."""
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        _gain_node(fmus["gain"], drivenVariable="follow"),
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.1, "stopTime": 1.0},
        events=[{"name": "hold", "when": "clock.y >= 0.3", "drives": "g", "until": "clock.y >= 0.6"}])
    rows = read_rows(run_project(cfg, tmp_path / "runs"))
    clock, y, modes = column(rows, "clock.y"), column(rows, "g.y"), [r["mode"] for r in rows]
    assert modes.count("hold") == 3 and modes[-1] == "free"
    for k in range(1, len(rows)):
        expected = clock[k - 1] if modes[k - 1] == "hold" else 2.0 * clock[k - 1] + 0.5
        assert math.isclose(y[k], expected, abs_tol=1e-12), (k, modes[k - 1])


def _rewrite(src: Path, dst: Path, edit) -> Path:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            name, data = edit(item.filename, zin.read(item.filename))
            if name:
                zout.writestr(name, data)
    return dst


def test_fmu_without_co_simulation(tmp_path, fmus):
    def to_me(name, data):
        if name == "modelDescription.xml":
            text = re.sub(r"<CoSimulation[^>]*/>", '<ModelExchange modelIdentifier="GainModel"/>', data.decode())
            return name, text.encode()
        return name, data
    me = _rewrite(fmus["gain"], tmp_path / "me.fmu", to_me)
    with pytest.raises(FmuError, match="node 'g': me.fmu has no co-simulation interface"):
        _instance(tmp_path, me, _gain_node(me, interface="CoSimulation"))
    # Taken at its word it runs as Model Exchange; its binary (pythonfmu's) has no such functions.
    with pytest.raises(FmuError, match=r"node 'g': me.fmu: its binary cannot be loaded as ModelExchange \(.*fmi2"):
        _instance(tmp_path, me, _gain_node(me))


def test_fmu_for_another_platform(tmp_path, fmus):
    def windows_only(name, data):
        if name.startswith("binaries/") and not name.startswith("binaries/win64"):
            return None, data
        return name, data
    win = _rewrite(fmus["gain"], tmp_path / "win.fmu", windows_only)
    with pytest.raises(FmuError, match=r"node 'g': win.fmu has binaries for win64, not for this one \(linux64\)"):
        _instance(tmp_path, win, _gain_node(win))


def test_an_fmi_1_fmu_whose_binary_cannot_load_is_named(tmp_path, fmus):
    # A valid FMI 1.0 co-simulation description over a binary that is no library.
    old = tmp_path / "old.fmu"
    with zipfile.ZipFile(old, "w") as z:
        z.writestr("modelDescription.xml", (
            '<?xml version="1.0"?><fmiModelDescription fmiVersion="1.0" modelName="m" modelIdentifier="m" '
            'guid="{0}" numberOfContinuousStates="0" numberOfEventIndicators="0"><ModelVariables>'
            '<ScalarVariable name="y" valueReference="0" causality="output"><Real/></ScalarVariable>'
            '<ScalarVariable name="u" valueReference="1" causality="input"><Real start="0"/></ScalarVariable>'
            '</ModelVariables><Implementation><CoSimulation_StandAlone><Capabilities/>'
            '</CoSimulation_StandAlone></Implementation></fmiModelDescription>'))
        z.writestr("binaries/linux64/m.so", b"\x7fELF")
    here = os.getcwd()
    with pytest.raises(FmuError, match="node 'g': old.fmu: its binary cannot be loaded as CoSimulation"):
        _instance(tmp_path, old, _gain_node(old, parameters={}, output=["y"]))
    assert os.getcwd() == here  # fmpy leaves a failed load's folder as the cwd; the node goes back


def test_a_pythonfmu_step_that_returns_false_ends_the_run_where_the_fmu_says(tmp_path, fmus):
    # pythonfmu answers a do_step that returns False with fmi2Discard and reports fmi2Terminated:
    # the FMU ends the simulation, which a master treats as the end of the run (a discard that
    # is no termination is a failure: tests/test_fmu_termination.py).
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        _gain_node(fmus["gain"], parameters={"fail_at": 0.5}),
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.1, "stopTime": 1.0, "stepTimeout": 5.0})
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress")
    assert res.returncode == 0, res.stderr
    assert "node 'g' ended the simulation at t=0.5 s (after step 5): GainModel.fmu asked to terminate" in res.stdout
    assert "Traceback" not in res.stderr
    run = next((tmp_path / "runs").iterdir())
    assert len(read_rows(run)) == 6  # T_0..T_5 recorded before the step the FMU ended in
    assert meta(run)["ended_by"]["node"] == "g"


def test_missing_fmu_file_and_bad_parameter(tmp_path, fmus):
    cfg = write_project(tmp_path / "p.json", [_gain_node(tmp_path / "nope.fmu")])
    res = hycosim("node", "g", str(cfg), timeout=60)
    assert res.returncode == 2 and "nope.fmu does not exist" in res.stderr
    with pytest.raises(FmuError, match="parameter 'gain' is not a variable of GainModel.fmu"):
        _instance(tmp_path, fmus["gain"], _gain_node(fmus["gain"], parameters={"gain": 1.0})).initialize(0.0)
    # a value the variable's type cannot take: named before the FMU is loaded, not a ValueError
    for value in ("two", [2.0], True):
        with pytest.raises(FmuError, match=r"parameter 'k' is a Real variable of GainModel.fmu, which .* is not"):
            _instance(tmp_path, fmus["gain"], _gain_node(fmus["gain"], parameters={"k": value}))
    cfg = write_project(tmp_path / "q.json", [_gain_node(fmus["gain"], parameters={"k": "2.0"})])
    res = hycosim("validate", str(cfg))
    assert res.returncode == 2 and "parameter 'k' is a Real variable of GainModel.fmu, which \"2.0\" is not" in res.stderr


@given(value=st.floats(allow_nan=True, allow_infinity=True) | st.integers(-10 ** 20, 10 ** 20) | st.booleans()
       | st.text(max_size=4) | st.none(), low=st.sampled_from([None, "0.001", "-5", "x"]),
       high=st.sampled_from([None, "100", "0", ""]))
def test_a_parameter_is_set_only_within_the_range_its_variable_declares(value, low, high):
    """An FMU's variable may declare a min and a max; a value outside them (which the FMU may
    refuse, or clamp without a word) is named before the FMU loads. A bound that is no number
    (the FMU's own fault) holds nothing."""
    from fmpy.model_description import ModelDescription, ScalarVariable

    from hycosim.fmi.loader import check_parameters

    var = ScalarVariable("k", 0)
    var.type, var.min, var.max = "Real", low, high
    md = ModelDescription()
    md.modelVariables.append(var)
    try:
        check_parameters(md, "g", {"k": value}, Path("M.fmu"))
    except FmuError as exc:
        assert str(exc).startswith("node 'g': parameter 'k' is ")
        refused = True
    else:
        refused = False
    number = type(value) in (int, float)
    below = low not in (None, "x") and number and value < float(low)
    above = high not in (None, "") and number and value > float(high)
    assert refused == (not number or not math.isfinite(value) or below or above)


def test_model_fmu_helper_errors_name_the_script(tmp_path):
    with pytest.raises(ModelFmuError, match="no such model script"):
        build_model_fmu(tmp_path / "missing.py", tmp_path)
    broken = tmp_path / "broken.py"
    broken.write_text("def (:\n")
    with pytest.raises(ModelFmuError, match=f"{broken}: packaging as FMI 2.0 failed: .*SyntaxError"):
        build_model_fmu(broken, tmp_path)


def test_a_process_that_loaded_a_model_fmu_still_builds_whole_ones(tmp_path, fmus):
    """A pythonfmu FMU loaded in-process imports the copy of pythonfmu in its resources (no
    binaries there): FMUs built afterwards in that process must still carry their binaries."""
    import sys
    import zipfile

    instance = _instance(tmp_path, fmus["gain"], _gain_node(fmus["gain"]))
    try:
        assert "resources" in sys.modules["pythonfmu"].__file__  # the FMU's own copy is the one imported
        built = build_model_fmu(MODELS / "gain_model.py", tmp_path / "again")
    finally:
        instance.close()
    assert "binaries/linux64/GainModel.so" in zipfile.ZipFile(built).namelist()


def test_inspect_lists_capabilities_variables_and_mapping(tmp_path, fmus):
    res = hycosim("fmu", "inspect", str(fmus["ball"]))
    assert res.returncode == 0, res.stderr
    assert "canGetAndSetFMUstate" in res.stdout and "impacts" in res.stdout
    cfg = write_project(tmp_path / "p.json", [_gain_node(fmus["gain"])])
    res = hycosim("fmu", "inspect", str(fmus["gain"]), "--config", str(cfg))
    assert res.returncode == 0, res.stderr
    line = next(l for l in res.stdout.splitlines() if "│ n " in l)
    assert "count" in line and "output" in line
    bad = write_project(tmp_path / "bad.json", [_gain_node(fmus["gain"], output=["speed"])])
    res = hycosim("fmu", "inspect", str(fmus["gain"]), "--config", str(bad))
    assert res.returncode == 2 and "'speed'" in res.stderr
    driven = write_project(tmp_path / "driven.json", [_gain_node(fmus["gain"], drivenVariable="follow")])
    res = hycosim("fmu", "inspect", str(fmus["gain"]), "--config", str(driven))
    assert res.returncode == 0 and "(driven flag)" in res.stdout and "follow" in res.stdout
    bad = write_project(tmp_path / "bad2.json", [_gain_node(fmus["gain"], drivenVariable="k")])
    res = hycosim("fmu", "inspect", str(fmus["gain"]), "--config", str(bad))
    assert res.returncode == 2 and "drivenVariable 'k' of GainModel.fmu is a parameter, not an input" in res.stderr


def _ball_project(tmp_path: Path, fmu: Path, extra_nodes: list | None = None, **cosim) -> Path:
    settings = {"stepSize": 0.05, "stopTime": 0.8}
    settings.update(cosim)
    nodes = [{"nodeName": "ball", "UID": 1, "fmu": str(fmu), "parameters": {"h": 1.0},
              "output": ["h", "v", {"name": "impacts", "type": "Integer"}]}, *(extra_nodes or [])]
    return write_project(tmp_path / "p.json", nodes, events=[
        {"name": "bounced", "when": "ball.impacts >= 1", "drives": "ball", "until": "ball.impacts >= 2"}], cosim=settings)


def test_rollback_locates_the_impact_within_tolerance(tmp_path, fmus):
    tol = 1e-4
    cfg = _ball_project(tmp_path, fmus["ball"], eventTolerance=tol)
    run = run_project(cfg, tmp_path / "runs")
    t_impact = math.sqrt(2 * 1.0 / G)
    event = json.loads((run / "events.jsonl").read_text().splitlines()[0])
    assert 0 <= event["t"] - t_impact <= tol
    assert event["localised"]["retries"] >= math.ceil(math.log2(0.05 / tol))
    assert meta(run)["event_localisation"] == f"rollback and bisection to {tol:g} s"
    rows = read_rows(run)
    t = column(rows, "t")
    k = event["step"]
    assert t[k] == event["t"] and rows[k]["mode"] == "bounced"
    assert math.isclose(t[k + 1] - t[k], 0.05, rel_tol=1e-9)  # a new grid from the event on
    assert math.isclose(t[-1], 0.8, abs_tol=1e-12)  # the last step is shortened to stopTime
    for i in range(k):  # before the impact, exact free fall at the recorded points
        assert math.isclose(float(rows[i]["ball.h"]), 1.0 - G * t[i] ** 2 / 2, abs_tol=1e-9)


def test_without_rollback_the_event_falls_on_the_grid_and_meta_says_why(tmp_path, fmus):
    cfg = _ball_project(tmp_path, fmus["ball"], [{"nodeName": "clock", "UID": 2, "model": "tests.nodes:Clock", "output": ["y"]}],
                        eventTolerance=1e-4)
    run = run_project(cfg, tmp_path / "runs")
    event = json.loads((run / "events.jsonl").read_text().splitlines()[0])
    assert math.isclose(event["t"], math.ceil(math.sqrt(2 / G) / 0.05) * 0.05, abs_tol=1e-9)
    assert "localised" not in event
    assert meta(run)["event_localisation"] == "none: fixed macro steps (clock cannot get and set state)"
