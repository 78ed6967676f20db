"""An FMU that asks to end the simulation ends the run cleanly; a discard is a failure that says so.

FMI 2: ``fmi2DoStep`` returns ``fmi2Discard`` and ``fmi2GetBooleanStatus(fmi2Terminated)`` is
true (a C FMU built here, since pythonfmu's FMI 2 export has no status calls); FMI 3:
``terminateSimulation`` (a pythonfmu3 FMU).
"""

from __future__ import annotations

import shutil
import subprocess
import uuid
import zipfile
from pathlib import Path

import pytest

from hycosim.bridge.model_fmu import build_model_fmu
from tests.helpers import REPO, column, hycosim, meta, read_rows, write_project

FMI_HEADERS = Path(__import__("fmpy").__file__).parent / "c-code"

_MODEL_DESCRIPTION = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Ending" guid="{guid}" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="ending" canHandleVariableCommunicationStepSize="true"/>
  <ModelVariables>
    <ScalarVariable name="x" valueReference="0" causality="output" variability="continuous" initial="exact">
      <Real start="0"/></ScalarVariable>
    <ScalarVariable name="end_at" valueReference="1" causality="parameter" variability="fixed" initial="exact">
      <Real start="1e9"/></ScalarVariable>
    <ScalarVariable name="discard_only" valueReference="0" causality="parameter" variability="fixed" initial="exact">
      <Boolean start="false"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1"/></Outputs></ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    if shutil.which("gcc") is None:
        pytest.skip("needs gcc")
    out = tmp_path_factory.mktemp("ending")
    so = out / "ending.so"
    subprocess.run(["gcc", "-shared", "-fPIC", "-O1", f"-I{FMI_HEADERS}", "-o", str(so),
                    str(REPO / "tests" / "c" / "ending_fmu2.c")], check=True, capture_output=True)
    fmu2 = out / "Ending.fmu"
    with zipfile.ZipFile(fmu2, "w") as z:
        z.writestr("modelDescription.xml", _MODEL_DESCRIPTION.format(guid=uuid.uuid4()))
        z.write(so, "binaries/linux64/ending.so")
    return {"2": fmu2, "3": build_model_fmu(REPO / "tests" / "models" / "ending_model3.py", out, fmi_version="3.0")}


def _project(tmp_path: Path, fmu: Path, discard: bool, fmi: str) -> Path:
    flag = "discard_only" if fmi == "2" else "discard"
    return write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "e", "UID": 2, "fmu": str(fmu), "parameters": {"end_at": 0.25, flag: discard}, "output": ["x"]},
    ], cosim={"stepSize": 0.1, "stopTime": 1.0, "stepTimeout": 10.0})


@pytest.mark.parametrize("where", ["--processes", "--in-process"])
@pytest.mark.parametrize("fmi", ["2", "3"])
def test_an_fmu_that_asks_to_terminate_ends_the_run_cleanly_naming_node_and_time(tmp_path, fmus, fmi, where):
    cfg = _project(tmp_path, fmus[fmi], discard=False, fmi=fmi)
    res = hycosim("run", str(cfg), where, "--runs-dir", str(tmp_path / "runs"), "--no-progress")
    assert res.returncode == 0, res.stderr
    ended_at = 0.25 if fmi == "2" else 0.3  # pythonfmu3 reports the step's end as lastSuccessfulTime
    assert f"node 'e' ended the simulation at t={ended_at:g} s" in res.stdout
    assert "lost" not in res.stdout + res.stderr
    run = next((tmp_path / "runs").iterdir())
    m = meta(run)
    assert m["status"] == "completed" and m["ended_by"]["node"] == "e"
    assert m["ended_by"]["t"] == pytest.approx(ended_at) and m["ended_by"]["step"] == 3
    rows = read_rows(run)
    # T_0..T_2, then the point the FMU ended at with its outputs there (as FMPy records it).
    # The FMI 2 FMU ended inside the step from 0.2: the clock's outputs are held from 0.2. The
    # FMI 3 FMU said it ended at the step's end: the clock's outputs there are recorded.
    assert column(rows, "t") == pytest.approx([0.0, 0.1, 0.2, ended_at])
    assert column(rows, "e.x") == pytest.approx([0.0, 0.1, 0.2, 0.25])
    assert column(rows, "clock.y") == pytest.approx([0.0, 0.1, 0.2, 0.2 if fmi == "2" else 0.3])


@pytest.mark.parametrize("where", ["--processes", "--in-process"])
@pytest.mark.parametrize("fmi", ["2", "3"])
def test_a_discard_without_termination_is_a_failure_whose_headline_names_the_discard(tmp_path, fmus, fmi, where):
    cfg = _project(tmp_path, fmus[fmi], discard=True, fmi=fmi)
    res = hycosim("run", str(cfg), where, "--runs-dir", str(tmp_path / "runs"), "--no-progress")
    assert res.returncode == 3
    headline = res.stderr.splitlines()[0]
    assert "node 'e'" in headline and f"discarded doStep from t=0.2 s by 0.1 s (fmi{fmi}Discard)" in headline
    assert "liveliness" not in res.stderr and "Traceback" not in res.stderr
    run = next((tmp_path / "runs").iterdir())
    m = meta(run)
    assert m["status"] == "failed" and "discarded doStep" in m["reason"]
    assert len(read_rows(run)) == 3


@pytest.mark.parametrize("end_at, points", [(0.25, 2), (0.72, 7), (0.05, 0)])
def test_an_fmu_ending_inside_a_batched_release_ends_the_records_where_one_release_a_step_would(
        tmp_path, fmus, end_at, points):
    """The clock steps every 5 base steps and nothing links the two, so releases span 5 base
    steps; the FMU ends inside one: the run ends cleanly, naming it, and the records hold the
    points it reached (its steps before the last came with its END) and the point it ended at,
    exactly as with one release per base step."""
    runs = {}
    for batch in (True, False):
        cfg = write_project(tmp_path / f"p-{batch}.json", [
            {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"], "stepSize": 0.5},
            {"nodeName": "e", "UID": 2, "fmu": str(fmus["2"]), "parameters": {"end_at": end_at}, "output": ["x"]},
        ], cosim={"stepSize": 0.1, "stopTime": 1.0, "stepTimeout": 10.0, "batchReleases": batch})
        res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / f"runs-{batch}"), "--no-progress")
        assert res.returncode == 0, res.stderr
        assert f"node 'e' ended the simulation at t={end_at:g} s" in res.stdout
        runs[batch] = next((tmp_path / f"runs-{batch}").iterdir())
    m = meta(runs[True])
    assert m["coupling"].endswith("releases batched over 5 base steps")
    # The points every node reached, then the one the FMU ended at (its x there is end_at).
    assert m["status"] == "completed" and m["ended_by"]["node"] == "e" and m["ended_by"]["step"] == points + 1
    rows = read_rows(runs[True])
    assert column(rows, "t") == pytest.approx([0.1 * i for i in range(points + 1)] + [end_at])
    assert column(rows, "e.x")[-1] == pytest.approx(end_at)
    assert (runs[True] / "values.csv").read_bytes() == (runs[False] / "values.csv").read_bytes()
    assert meta(runs[False])["ended_by"]["step"] == points + 1


@pytest.mark.parametrize("fmi", ["2", "3"])
def test_the_records_of_an_fmu_that_terminates_are_fmpys_point_for_point(tmp_path, fmus, fmi):
    """FMPy's simulate_fmu records an FMU that asks to terminate at the time it ended, with its
    outputs there; a hycosim run of the FMU alone records the same points and values."""
    from fmpy import simulate_fmu

    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "e", "UID": 1, "fmu": str(fmus[fmi]), "parameters": {"end_at": 0.25}, "output": ["x"]}],
        cosim={"stepSize": 0.1, "stopTime": 1.0, "stepTimeout": 10.0})
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress")
    assert res.returncode == 0, res.stderr
    rows = read_rows(next((tmp_path / "runs").iterdir()))
    ref = simulate_fmu(str(fmus[fmi]), start_values={"end_at": 0.25}, stop_time=1.0, step_size=0.1,
                       output_interval=0.1, output=["x"])
    assert column(rows, "t") == list(ref["time"]) and column(rows, "e.x") == list(ref["x"])
    assert len(rows) == 4
