"""FMI 3 beyond scalars: an FMU with array variables sized by structural parameters runs
through its scalar ports as fmpy runs it, at its default sizes and at sizes the node's
parameters set; what hycosim does not run (a port without its array variable's shape,
clocks it cannot tick, scheduled execution) is refused by name before a run, by `validate` and `run` alike,
and `fmu inspect` shows it. Array ports themselves: tests/test_arrays.py."""

from __future__ import annotations

import json

import pytest
from fmpy import simulate_fmu
from hypothesis import given
from hypothesis import strategies as st

from hycosim.core.config import load_project
from hycosim.fmi.loader import MAX_ELEMENTS, FmuError, check_fmu
from tests.fmi3_fmus import build
from tests.helpers import column, hycosim, read_rows, run_project, write_project


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    return build(tmp_path_factory.mktemp("fmi3"))


def _project(tmp_path, fmu, output=("s",), input=("g",), parameters=None, stop=0.5):
    node = {"nodeName": "ss", "UID": 1, "fmu": str(fmu), "input": list(input), "output": list(output)}
    if parameters is not None:
        node["parameters"] = parameters
    return write_project(tmp_path / "p.json", [node], cosim={"stepSize": 0.01, "stopTime": stop})


@pytest.mark.parametrize("sizes", [{}, {"n": 4, "r": 2, "m": 1}], ids=["default sizes", "sizes set by parameters"])
def test_an_array_fmu_runs_through_its_scalar_ports_to_fmpys_values(tmp_path, fmus, sizes):
    run_dir = run_project(_project(tmp_path, fmus["statespace"], parameters=sizes or None), tmp_path / "runs")
    rows = read_rows(run_dir)
    ref = simulate_fmu(str(fmus["statespace"]), stop_time=0.5, output_interval=0.01, output=["s"],
                       start_values=sizes)
    assert len(rows) == len(ref) == 51
    assert column(rows, "t") == list(ref["time"])
    assert column(rows, "ss.s") == list(ref["s"])  # to the bit: the same calls on the same grid


def test_the_structural_parameters_change_what_runs(tmp_path, fmus):
    """Set before the FMU is initialised, they size its state: the sum of y differs."""
    default = read_rows(run_project(_project(tmp_path, fmus["statespace"], stop=0.05), tmp_path / "a"))
    resized = read_rows(run_project(_project(tmp_path, fmus["statespace"], parameters={"n": 5}, stop=0.05),
                                    tmp_path / "b"))
    assert column(default, "ss.s")[0] != column(resized, "ss.s")[0]


@pytest.mark.parametrize("case, parameters, said", [
    ("output array", {}, "output 'y' maps to variable 'y' of StateSpace.fmu, an array of shape [3]"),
    ("output array resized", {"r": 5}, "output 'y' maps to variable 'y' of StateSpace.fmu, an array of shape [5]"),
    ("fixed-size output array", {}, "output 'pair' maps to variable 'pair' of StateSpace.fmu, an array of shape [2]"),
    ("input array", {}, "input 'u' maps to variable 'u' of StateSpace.fmu, an array of shape [2]"),
    ("a dimension of zero", {"r": 0}, "variable 'C' would have a dimension of 0 (structural parameter 'r')"),
    ("a huge array", {"n": 300}, f"variable 'A' would hold 90,000 elements (shape [300, 300]); hycosim takes "
                                 f"at most {MAX_ELEMENTS:,}"),
])
def test_what_the_model_description_shows_cannot_run_is_refused_before_a_run(tmp_path, fmus, case, parameters, said):
    output = {"output array": ["y"], "output array resized": ["y"], "fixed-size output array": ["pair"]}.get(case, ["s"])
    input = ["u"] if case == "input array" else ["g"]
    cfg = _project(tmp_path, fmus["statespace"], output=output, input=input, parameters=parameters)
    # validate and run alike refuse it from the model description, before a run (exit 2).
    for command, code in (("validate", 2), ("run", 2)):
        res = hycosim(command, str(cfg), *(["--runs-dir", str(tmp_path / "runs")] if command == "run" else []))
        assert res.returncode == code, (command, res.stdout, res.stderr)
        assert "node 'ss'" in res.stderr and said in res.stderr.replace("\n", " "), (command, res.stderr)
        assert "Traceback" not in res.stderr


@pytest.mark.parametrize("kind, said", [
    ("triggered", "Triggered.fmu: hycosim cannot tick clock trip (triggered: it ticks on an event, not on a "
                  "schedule; hycosim does not follow such ticks yet)"),
    ("tunable", "Tunable.fmu: hycosim cannot tick clock tick (its interval is tunable; hycosim ticks clocks of a "
                "constant interval)"),
    ("no-event-mode", "NoEventMode.fmu has clock tick (periodic, every 0.1 s) but no event mode (hasEventMode), "
                      "in which FMI 3 co-simulation ticks clocks"),
    ("model-exchange", "ModelExchange.fmu has clock tick (periodic, every 0.1 s); hycosim ticks clocks of "
                       "co-simulation FMUs only"),
    ("scheduled", "Scheduled.fmu has only a scheduled-execution interface, which hycosim does not run"),
])
def test_clocks_hycosim_does_not_tick_and_scheduled_execution_are_named_and_refused(tmp_path, fmus, kind, said):
    for command in ("validate", "run"):
        res = hycosim(command, str(_project(tmp_path, fmus[kind])), *(["--runs-dir", str(tmp_path / "runs")]
                                                                       if command == "run" else []))
        assert res.returncode == 2 and said in res.stderr.replace("\n", " "), (command, res.stderr)
        assert "Traceback" not in res.stderr
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("kind, said", [("periodic", "clock tick (periodic, every 0.1 s)"),
                                        ("shifted", "clock tick (periodic, every 0.1 s from 0.05 s)")])
def test_validate_takes_an_fmu_whose_clocks_are_periodic_and_names_them(tmp_path, fmus, kind, said):
    res = hycosim("validate", str(_project(tmp_path, fmus[kind])))
    assert res.returncode == 0, res.stderr
    assert f"node 'ss': {said}, ticked in event mode at t0 + shift + k·interval" in " ".join(res.stdout.split())


def test_fmu_inspect_shows_shapes_and_clocks(fmus):
    res = hycosim("fmu", "inspect", str(fmus["triggered"]))
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    row = {line.split("│")[1].strip(): [c.strip() for c in line.split("│")[2:-1]] for line in lines
           if line.startswith("│") and len(line.split("│")) > 3}
    assert row["A"][3] == "[3, 3]" and row["y"][3] == "[3]" and row["pair"][3] == "[2]" and row["s"][3] == ""
    assert "clocks" in res.stdout
    assert row["tick"][:3] == ["input", "periodic", "0.1"] and row["trip"][:3] == ["output", "triggered", ""]
    assert row["tick"][4] == "yes" and row["trip"][4].startswith("no: triggered")
    assert "clocks: refused: Triggered.fmu: hycosim cannot tick clock trip" in " ".join(res.stdout.split())
    shifted = hycosim("fmu", "inspect", str(fmus["shifted"]))
    assert "│ tick │ input     │ periodic │ 0.1          │ 0.05      │ yes" in shifted.stdout
    assert "clocks: hycosim runs this FMU, ticking each clock at t0 + shift + k·interval in event mode" in \
        " ".join(shifted.stdout.split())


_sizes = st.one_of(st.integers(-5, 70_000), st.floats(allow_nan=True), st.text(max_size=3), st.none(), st.booleans(),
                   st.lists(st.integers(), max_size=2))


@given(parameters=st.dictionaries(st.sampled_from(["m", "n", "r"]), _sizes, max_size=3),
       output=st.sampled_from(["s", "y"]))
def test_any_structural_parameters_are_taken_or_refused_naming_the_node(tmp_path_factory, fmus, parameters, output):
    """Whatever a project file sets them to, with a port on a scalar or on an array they size: a
    size that fits is taken (an array port is then refused for being one), anything else is an
    FmuError naming the node (never another exception, never an array past the bound)."""
    tmp = tmp_path_factory.mktemp("p")
    cfg = tmp / "p.json"
    cfg.write_text(json.dumps({"serverIP": "tcp/127.0.0.1:7447", "nodeNum": 1, "linkNum": 0, "linkLists": [],
                               "nodeLists": [{"nodeName": "ss", "UID": 1, "fmu": str(fmus["statespace"]),
                                              "input": ["g"], "output": [output], "parameters": parameters}]}))
    try:
        spec = load_project(cfg).project.node("ss")
    except Exception as exc:  # noqa: BLE001 - the loader refuses a value JSON cannot give a parameter
        assert "ss" in str(exc) or "parameters" in str(exc)
        return
    sizes = {"m": 2, "n": 3, "r": 3, **parameters}
    fits = all(type(v) is int and 1 <= v for v in sizes.values()) and max(
        sizes["n"] * sizes["n"], sizes["n"] * sizes["m"], sizes["r"] * sizes["n"], sizes["r"] * sizes["m"]) <= MAX_ELEMENTS
    try:
        check_fmu(fmus["statespace"], spec)
    except FmuError as exc:
        assert not fits or output == "y", exc
        assert str(exc).startswith("node 'ss': "), exc
        if fits:
            assert f"an array of shape [{sizes['r']}]" in str(exc)
        return
    assert fits and output == "s"


def test_fmi3_string_binary_and_float32_ports_carry_their_values(tmp_path, fmus):
    """The FMI 3 types beside Float64: a String and a Binary input each read back through an
    output that depends on it, and a Float32 computed in single precision."""
    import numpy as np

    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "src", "UID": 1, "model": "tests.nodes:Bytes",
         "output": [{"name": "label", "type": "String"}, {"name": "blob", "type": "Binary"}, "w"]},
        {"nodeName": "ss", "UID": 2, "fmu": str(fmus["statespace"]),
         "input": [{"name": "label", "type": "String"}, {"name": "blob", "type": "Binary"}, "k32"],
         "output": [{"name": "greeting", "type": "String"}, {"name": "blob_out", "type": "Binary"}, "s32", "s"]},
    ], [{"from": "src.label", "to": "ss.label"}, {"from": "src.blob", "to": "ss.blob"}, {"from": "src.w", "to": "ss.k32"}],
        cosim={"stepSize": 0.01, "stopTime": 0.2})
    rows = read_rows(run_project(cfg, tmp_path / "runs"))
    assert len(rows) == 21
    for k in range(1, len(rows)):
        before, now = rows[k - 1], rows[k]
        assert now["ss.greeting"] == f"hello {before['src.label']}"
        assert bytes.fromhex(now["ss.blob_out"]) == bytes.fromhex(before["src.blob"])[::-1]
        assert float(now["ss.s32"]) == float(np.float32(float(now["ss.s"])) + np.float32(float(before["src.w"])))
    assert {r["src.label"] for r in rows} == {f"n{k}" for k in range(21)}
