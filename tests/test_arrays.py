"""Array ports: an FMI 3 FMU's array variables and a Python node's arrays travel as arrays,
link whole (element-wise transformations) or one element into a scalar, are recorded one
column per element, and are replayed, recovered and run in process as scalars are; anything
that does not fit is named before a run or dropped on the wire."""

from __future__ import annotations

import json
import math

import numpy
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hycosim.core import frames
from hycosim.core.config import load_project, parse_project
from hycosim.core.schema import Node
from hycosim.master.intake import Dropped, Intake
from hycosim.master.retakes import input_change
from tests.fmi3_fmus import build
from tests.helpers import column, hycosim, meta, read_rows, run_killing, run_project, write_project


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    return build(tmp_path_factory.mktemp("fmi3"))


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    from benchmarks._small_fmus import build as build_small

    return build_small(tmp_path_factory.mktemp("small"))


def _project(tmp_path, fmu, sizes=None, stop=0.5, cosim=None, name="arr", vec=None, feedthrough=None, **changes):
    """ss (the state-space FMU: u of m elements in, y of r out) fed by vec (a Python node's array
    v, doubled on the way), ss.y back into vec.a whole, and its element 1 into a gain (and,
    with ``feedthrough``, its last element into that FMI 2 FMU's scalar input)."""
    m, r = (sizes or {}).get("m", 2), (sizes or {}).get("r", 3)
    ss = {"nodeName": "ss", "UID": 1, "fmu": str(fmu), "input": [{"name": "u", "shape": [m]}],
          "output": [{"name": "y", "shape": [r]}, "s"]}
    if sizes:
        ss["parameters"] = sizes
    vec = vec or {"nodeName": "vec", "UID": 2, "model": "tests.nodes:Vector", "input": [{"name": "a", "shape": [r]}],
                  "output": [{"name": "v", "shape": [m]}, "total"]}
    g = {"nodeName": "g", "UID": 3, "model": "gain", "input": ["u"], "output": ["y"]}
    links = [{"from": "vec.v", "to": "ss.u", "factor": 2.0}, {"from": "ss.y", "to": "vec.a"},
             {"from": "ss.y[1]", "to": "g.u"}]
    nodes = [ss, vec, g]
    if feedthrough is not None:
        nodes.append({"nodeName": "ft", "UID": 4, "fmu": str(feedthrough), "input": ["u"], "output": ["y"]})
        links.append({"from": f"ss.y[{r - 1}]", "to": "ft.u"})
    for key, value in changes.items():
        node, _, field = key.partition("__")
        next(n for n in nodes if n["nodeName"] == node)[field] = value
    return write_project(tmp_path / f"{name}.json", nodes, links,
                         cosim={"stepSize": 0.01, "stopTime": stop, **(cosim or {})}, name=name)


def _elements(rows, label, size):
    return [[float(row[f"{label}[{i}]"]) for i in range(size)] for row in rows]


def _fmpy_outputs(fmu, sizes, inputs, times, arrays=None):
    """y after initialisation and after each step of the FMU stepped alone by fmpy's FMU3Slave,
    its u set before each step to the given values (hycosim's, from its records); ``arrays``:
    array parameters set (flat) after the sizes."""
    md = read_model_description(str(fmu))
    unzipped = extract(str(fmu))
    slave = FMU3Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="ref")
    slave.instantiate()
    vr = {v.name: v.valueReference for v in md.modelVariables}
    for name, value in sizes.items():
        slave.setUInt64([vr[name]], [value])
    for name, value in (arrays or {}).items():
        slave.setFloat64([vr[name]], value)
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    r = sizes.get("r", 3)
    ys = [slave.getFloat64([vr["y"]], r)]
    for u, t, t_next in zip(inputs, times, times[1:]):
        slave.setFloat64([vr["u"]], u)
        slave.doStep(currentCommunicationPoint=t, communicationStepSize=t_next - t)
        ys.append(slave.getFloat64([vr["y"]], r))
    slave.terminate()
    slave.freeInstance()
    return ys


@pytest.mark.parametrize("sizes", [{}, {"m": 1, "n": 4, "r": 2}], ids=["default sizes", "sizes set by parameters"])
def test_an_array_fmu_coupled_through_arrays_and_one_element_runs_to_fmpys_values(tmp_path, fmus, small, sizes):
    run_dir = run_project(_project(tmp_path, fmus["statespace"], sizes, feedthrough=small["Feedthrough"]),
                          tmp_path / "runs")
    rows = read_rows(run_dir)
    m, r = sizes.get("m", 2), sizes.get("r", 3)
    header = list(rows[0])
    assert [c for c in header if c.startswith("ss.y")] == [f"ss.y[{i}]" for i in range(r)]
    assert [c for c in header if c.startswith("ss.u")] == [f"ss.u[{i}]" for i in range(m)]
    y, u = _elements(rows, "ss.y", r), _elements(rows, "ss.u", m)
    v, a = _elements(rows, "vec.v", m), _elements(rows, "vec.a", r)
    times = column(rows, "t")
    assert len(rows) == 51
    # The FMU stepped alone on hycosim's inputs gives hycosim's outputs, element by element, to the bit.
    assert y == _fmpy_outputs(fmus["statespace"], sizes, u, times)
    # Links: v doubled element-wise into u; y whole into a; y[1] alone into the gain; vec sums a.
    assert u == [[2.0 * x + 0.0 for x in row] for row in v]
    assert all(row_v == [(i + 1) * t for i in range(m)] for row_v, t in zip(v, times))
    assert a == y and column(rows, "g.u") == [row[1] for row in y]
    # One element into a scalar FMU (FMI 2, y = u after each step).
    assert column(rows, "ft.u") == [row[-1] for row in y] and column(rows, "ft.y")[1:] == column(rows, "ft.u")[:-1]
    assert column(rows, "vec.total")[1:] == [sum(row) for row in y[:-1]]
    assert len(set(map(tuple, y))) > 40  # the inputs move the state: not a constant


def test_array_parameters_flat_or_nested_are_set_at_the_sizes_structural_parameters_give(tmp_path, fmus):
    """A at n = 4 nested as its shape, C (r x n) and x0 flat: the run gives what fmpy gives the FMU
    with the same values set, and its first row is C x0 + D u0 of them, not of the defaults."""
    A = [[-1.0 - i if i == j else 0.1 * (j - i) for j in range(4)] for i in range(4)]
    C = [0.5, -0.25, 1.0, 2.0, 0.0, 1.5, -1.0, 0.75]
    x0 = [2.0, -1.0, 0.5, 3.0]
    sizes = {"m": 1, "n": 4, "r": 2}
    run_dir = run_project(_project(tmp_path, fmus["statespace"], {**sizes, "A": A, "C": C, "x0": x0}),
                          tmp_path / "runs")
    rows = read_rows(run_dir)
    y, u = _elements(rows, "ss.y", 2), _elements(rows, "ss.u", 1)
    flat = {"A": [a for row in A for a in row], "C": C, "x0": x0}
    assert y == _fmpy_outputs(fmus["statespace"], sizes, u, column(rows, "t"), flat)
    D0 = 0.1  # statespace3.c's default D[0][0]; u is 0 at t0
    assert y[0] == [sum(C[l * 4 + i] * x0[i] for i in range(4)) + D0 * u[0][0] * (l == 0) for l in range(2)]


def test_arrays_run_in_process_replayed_and_recovered_to_the_same_records(tmp_path, fmus):
    reference = run_project(_project(tmp_path, fmus["statespace"], stop=3.0), tmp_path / "a")
    expected = (reference / "values.csv").read_bytes()
    # in one process
    res = hycosim("run", str(_project(tmp_path, fmus["statespace"], stop=3.0)), "--in-process",
                  "--runs-dir", str(tmp_path / "b"), "--no-progress")
    assert res.returncode == 0, res.stderr
    assert (next((tmp_path / "b").iterdir()) / "values.csv").read_bytes() == expected
    # the Python node played back from the reference's records
    played = _project(tmp_path, fmus["statespace"], stop=3.0, name="played", vec__replay=str(reference))
    assert (run_project(played, tmp_path / "c") / "values.csv").read_bytes() == expected
    # both array nodes killed mid-run, restored from checkpoints
    cfg = _project(tmp_path, fmus["statespace"], stop=3.0, cosim={"checkpointEvery": 0.25, "attachTimeout": 20.0},
                   g__parameters={"work_s": 0.002})
    code, err = run_killing(cfg, tmp_path / "d", [("node ss", 80), ("node vec", 200)], "--restarts", "2")
    assert code == 0, err
    run = next((tmp_path / "d").iterdir())
    assert [r["node"] for r in meta(run)["recoveries"]] == ["ss", "vec"]
    assert (run / "values.csv").read_bytes() == expected


@pytest.mark.parametrize("case, said", [
    ({"link": {"from": "ss.y", "to": "g.u"}}, "shape mismatch: ss.y is an array of shape [3], g.u is a scalar"),
    ({"link": {"from": "ss.y[3]", "to": "g.u"}}, "ss.y[3] is out of range"),
    ({"link": {"from": "vec.total", "to": "ss.u"}}, "shape mismatch: vec.total is a scalar, ss.u is an array of shape [2]"),
    ({"link": {"from": "g.y", "to": "ss.u[0]"}}, "ss.u[0] names one element of an input"),
    ({"link": {"from": "vec.total[0]", "to": "g.u"}}, "vec.total[0] indexes a scalar port"),
    ({"ss__output": [{"name": "y", "shape": [4]}, "s"], "vec__input": [{"name": "a", "shape": [4]}]},
     "output 'y' (shape [4]) maps to variable 'y' of StateSpace.fmu, an array of shape [3]"),
    ({"ss__output": [{"name": "y", "shape": [3]}, "s", "pair"]},
     "output 'pair' maps to variable 'pair' of StateSpace.fmu, an array of shape [2] (give the port \"shape\": [2])"),
    ({"ss__output": [{"name": "y", "shape": [3]}, {"name": "s", "shape": [1]}]},
     "output 's' (shape [1]) maps to variable 's' of StateSpace.fmu, a scalar"),
    ({"vec__output": [{"name": "v", "shape": [0]}, "total"]}, "shape is one or more dimensions"),
    ({"vec__output": [{"name": "v", "shape": [2], "type": "String"}, "total"]},
     "an array port holds Real, Integer or Boolean values, not String"),
    ({"event": {"name": "e", "when": "ss.y > 1", "drives": "g", "until": "ss.s > 5"}}, "guard names ss.y, an array port"),
    ({"ss__parameters": {"A": [1.0, 2.0]}}, "parameter 'A' is an array variable of StateSpace.fmu of shape [3, 3]: "
     "give a list of its 9 elements (row-major), or lists nested as its shape; [1.0, 2.0] is neither"),
    ({"ss__parameters": {"n": 2, "A": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]}},
     "parameter 'A' is an array variable of StateSpace.fmu of shape [2, 2]"),
    ({"ss__parameters": {"x0": [1.0, True, 0.5]}}, "parameter 'x0[1]' is a Float64 variable of StateSpace.fmu, "
     "which true is not"),
    ({"ss__parameters": {"s": [1.0]}}, "parameter 's' is a Float64 variable of StateSpace.fmu, which [1.0] is not"),
])
def test_arrays_that_do_not_fit_are_named_before_a_run(tmp_path, fmus, case, said):
    case = dict(case)
    link, event = case.pop("link", None), case.pop("event", None)
    cfg = _project(tmp_path, fmus["statespace"], **case)
    doc = json.loads(cfg.read_text())
    if link:
        doc["linkLists"][2] = link
    if event:
        doc["events"] = [event]
    cfg.write_text(json.dumps(doc))
    for command in ("validate", "run"):
        res = hycosim(command, str(cfg), *(["--runs-dir", str(tmp_path / "runs")] if command == "run" else []))
        assert res.returncode == 2, (command, res.stdout, res.stderr)
        assert said in res.stderr.replace("\n", " "), (command, res.stderr)
        assert "Traceback" not in res.stderr
    assert not (tmp_path / "runs").exists()  # refused before a run directory is made


def test_a_python_node_whose_array_output_has_another_size_fails_naming_the_port(tmp_path, fmus):
    cfg = _project(tmp_path, fmus["statespace"], vec__model="tests.nodes:VectorOfThree")
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress")
    assert res.returncode == 3, res.stderr
    assert "node 'vec': output 'v': 3 values for array port 'v' of shape [2] (2 elements)" in res.stderr
    assert "Traceback" not in res.stderr


_ELEMENT = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-2**63, 2**64 - 1), st.booleans(),
                     st.text(max_size=2), st.binary(max_size=2), st.none(), st.lists(st.floats(), max_size=2))


@given(value=st.one_of(st.lists(_ELEMENT, max_size=5), st.lists(st.floats(), min_size=3, max_size=3), _ELEMENT,
                       st.dictionaries(st.text(max_size=2), st.floats(), max_size=2)))
def test_an_array_output_on_the_wire_is_taken_exactly_when_it_fits_its_shape(value):
    """The server's intake: a value for a Real array of 3 is taken exactly when it is a list
    of three numbers (ints or floats, msgpack's types); anything else is dropped as a wrong
    type naming the port, and nothing else escapes."""
    spec = Node.model_validate({"nodeName": "n", "UID": 7, "output": [{"name": "y", "shape": [3]}, "s"]})
    intake = Intake([spec])
    payload = frames.encode(frames.OUTPUTS, 7, 4, 0.04, [value, 1.0])
    fits = type(value) is list and len(value) == 3 and all(type(x) in (float, int) for x in value)
    try:
        frame = intake.accept("n", payload)
    except Dropped as exc:
        assert not fits and exc.reason == "wrong type" and "n.y" in exc.detail, exc
        return
    assert fits and frame.values[0] == value


@given(value=st.one_of(st.lists(_ELEMENT, max_size=4), _ELEMENT))
def test_a_release_gives_a_node_an_array_input_only_of_its_size_and_type(value):
    """The node's check of a STEP: an Integer array input of 2 takes two ints, nothing else."""
    release = frames.decode(frames.encode(frames.STEP, 3, 0.03, 0.01, "free", {"n": [value, 0.5]}, [], {}))
    fits = type(value) is list and len(value) == 2 and all(type(x) is int for x in value)
    try:
        frames.check_release(release, "n", ((list,), (float, int)), input_arrays=((0, 2, (int,)),))
    except frames.FrameError as exc:
        assert not fits and "node 'n'" in str(exc)
        return
    assert fits


def test_an_iterated_step_measures_an_array_input_element_by_element():
    change, where, absolute = input_change({"n": [[1.0, 2.0, 3.5]]}, {"n": [[1.0, 2.0, 3.0]]}, {"n": ["n.a"]}, 1e-3)
    assert where == "n.a[2]" and absolute == 0.5 and math.isclose(change, 0.5 / (1e-3 * 3.5))
    assert input_change({"n": [[1.0, 2.0]]}, {"n": [[1.0, 2.0]]}, {"n": ["n.a"]}, 1e-3) == (0.0, "", 0.0)


@given(shape=st.lists(st.integers(1, 3), min_size=1, max_size=3), data=st.data())
def test_an_array_parameter_is_taken_flat_or_nested_exactly_as_its_shape(shape, data):
    from hycosim.fmi.loader import array_elements

    size = math.prod(shape)
    flat = list(range(size))
    nested = numpy.arange(size).reshape(shape).tolist()
    assert array_elements(flat, tuple(shape)) == flat
    assert array_elements(nested, tuple(shape)) == flat
    other = data.draw(st.lists(st.integers(1, 3), min_size=1, max_size=3).filter(lambda s: math.prod(s) != size))
    assert array_elements(numpy.arange(math.prod(other)).reshape(other).tolist(), tuple(shape)) is None
    drawn = data.draw(st.recursive(st.integers(), lambda inner: st.lists(inner, max_size=4)))
    got = array_elements(drawn, tuple(shape))
    assert got is None or (len(got) == size and got == _leaves(drawn))
    if got is not None and any(type(v) is list for v in drawn):  # nested: exactly as the shape
        assert numpy.asarray(drawn).shape == tuple(shape)


def _leaves(value):
    return [leaf for v in value for leaf in _leaves(v)] if type(value) is list else [value]


def test_ssp_export_names_array_ports_and_parameters(tmp_path, fmus):
    cfg = _project(tmp_path, fmus["statespace"], {"x0": [1.0, 2.0, 3.0]})
    res = hycosim("export", str(cfg), "-o", str(tmp_path / "out.ssp"))
    assert res.returncode == 2, res.stderr
    assert "nodeLists[0] (ss): array ports u, y; nodeLists[0] (ss): array parameter x0" in res.stderr.replace("\n", " ")
    assert load_project(cfg).project.node("ss").port("y").shape == (3,)


def test_a_python_node_gives_a_two_dimensional_array_row_major(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "vec", "UID": 1, "model": "tests.nodes:Vector", "input": [],
         "output": [{"name": "v", "shape": [2, 3]}, "total"]}], cosim={"stepSize": 0.01, "stopTime": 0.03})
    rows = read_rows(run_project(cfg, tmp_path / "runs"))
    assert [c for c in rows[0] if c.startswith("vec.v")] == [f"vec.v[{i}]" for i in range(6)]
    assert _elements(rows, "vec.v", 6) == [[(i + 1) * t for i in range(6)] for t in column(rows, "t")]


_ARRAY_PROJECT = {"projectName": "p", "nodeNum": 1, "linkNum": 0, "linkLists": [],
                  "nodeLists": [{"nodeName": "n", "UID": 1, "model": "gain",
                                 "input": [{"name": "u", "shape": [2], "type": "Integer"}],
                                 "output": [{"name": "y", "shape": [3]}]}]}


@given(outputs=st.one_of(st.lists(_ELEMENT, max_size=4), st.lists(st.floats(), min_size=3, max_size=3), _ELEMENT),
       inputs=st.one_of(st.lists(_ELEMENT, max_size=3), st.lists(st.integers(-9, 9), min_size=2, max_size=2)))
def test_a_checkpoint_holding_array_values_is_taken_exactly_when_they_fit(outputs, inputs):
    """A checkpoint's server state (a file a user may edit) is restored only with an array of its
    port's size and element type for every array port; otherwise it is passed over, naming the port."""
    from hycosim.master.checkpoints import misfit

    project = parse_project(_ARRAY_PROJECT).project
    server = {"outputs": {"n": [outputs]}, "inputs": {"n": [inputs]}, "mode": "free", "disarmed": [],
              "origin": 0.0, "t": 0.5, "histories": {}}
    fits_out = type(outputs) is list and len(outputs) == 3 and all(type(x) in (float, int) for x in outputs)
    fits_in = type(inputs) is list and len(inputs) == 2 and all(type(x) is int for x in inputs)
    said = misfit(server, project)
    assert (said is None) == (fits_out and fits_in), said
    if said is not None:
        assert ("of n: y" in said) if not fits_out else ("of n: u" in said)


@st.composite
def _array_csv(draw) -> str:
    """values.csv of a node with an array output of 2: the right header or one short of an
    element, rows whose cells may be broken or missing, a torn end."""
    header = draw(st.sampled_from(["step,t,mode,n.y[0],n.y[1]", "step,t,mode,n.y[0]", "step,t,mode,n.y"]))
    width = header.count(",") + 1
    lines = [header]
    for k in range(draw(st.integers(0, 4))):
        cells = [str(k), repr(k * 0.01), "free", *(repr(draw(st.floats(allow_nan=False))) for _ in range(width - 3))]
        if draw(st.booleans()) and width > 3:
            cells[draw(st.integers(3, width - 1))] = draw(st.text(max_size=4)).replace("\n", "")
        if draw(st.booleans()):
            cells.pop()
        lines.append(",".join(cells))
    text = "\n".join(lines) + "\n"
    return text[:draw(st.integers(0, len(text)))] if draw(st.booleans()) else text


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(values=_array_csv())
def test_a_recorded_array_is_played_back_whole_or_refused_naming_the_file(tmp_path, values):
    from hycosim.core.recordings import Recording, RecordingError

    doc = dict(_ARRAY_PROJECT)
    (tmp_path / "project.json").write_text(json.dumps(doc))
    (tmp_path / "values.csv").write_text(values)
    spec = Node.model_validate(doc["nodeLists"][0])
    try:
        rows = Recording(tmp_path).outputs(spec)
    except RecordingError as exc:
        assert str(tmp_path) in str(exc)
        return
    assert rows and all(len(v) == 1 and len(v[0]) == 2 and all(type(x) is float for x in v[0]) for _, v in rows)
