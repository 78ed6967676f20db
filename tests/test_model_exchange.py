"""Model Exchange FMUs as nodes: the node integrates them (CVode or Euler), with time, state and
step events inside a macro step, and matches FMPy's own simulation of the same FMU."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu

from hycosim.node.fmu_node import FmuNode
from hycosim.node.interface import NodeContext
from hycosim.core.schema import Node
from hycosim.core.config import load_project
from tests.helpers import column, hycosim, meta, read_rows, run_project, write_project
from tests.me_fmus import build_me_fmus


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    if shutil.which("gcc") is None:
        pytest.skip("needs gcc")
    return build_me_fmus(tmp_path_factory.mktemp("me"))


def _simulate(fmu: Path, entry: dict, h: float, stop: float) -> list[dict]:
    """The node's outputs at every point, stepped in this process (no co-simulation around it)."""
    spec = Node.model_validate(entry)
    node = FmuNode(spec, fmu)
    node.setup(NodeContext(spec.nodeName, spec.UID, list(spec.input), list(spec.output), dict(spec.parameters), h,
                           0.0, stop_time=stop))
    try:
        points = [node.outputs()]
        for k in range(round(stop / h)):
            node.step(k * h, h, {})
            points.append(node.outputs())
        return points
    finally:
        node.teardown()


def _ball(fmu: Path, **entry) -> dict:
    node = {"nodeName": "ball", "UID": 1, "fmu": str(fmu), "output": ["h", "v", {"name": "bounces", "type": "Integer"}]}
    node.update(entry)
    return node


@pytest.mark.parametrize("fmi", ["2.0", "3.0", "1.0"])
def test_a_model_exchange_fmu_runs_as_fmpy_simulates_it(tmp_path, fmus, fmi):
    """Two bounces in 1.5 s: CVode locates the state events inside the macro steps, as in FMPy
    (FMI 1.0: fmiInitialize and fmiEventUpdate in place of the event mode)."""
    fmu = fmus[{"2.0": "me", "3.0": "me3", "1.0": "me1"}[fmi]]
    cfg = write_project(tmp_path / "p.json", [_ball(fmu)], cosim={"stepSize": 0.01, "stopTime": 1.5})
    res = hycosim("validate", str(cfg))
    assert res.returncode == 0, res.stderr
    run = run_project(cfg, tmp_path / "runs")
    rows = read_rows(run)
    ref = simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode", stop_time=1.5,
                       output_interval=0.01, output=["h", "v", "bounces"], record_events=False)
    assert len(rows) == len(ref) == 151
    assert np.allclose(column(rows, "ball.h"), ref["h"], rtol=1e-5, atol=1e-6)
    assert np.allclose(column(rows, "ball.v"), ref["v"], rtol=1e-5, atol=1e-5)
    assert column(rows, "ball.bounces") == list(ref["bounces"])
    assert column(rows, "ball.bounces")[-1] == 2
    # Impact times (the node logs each event inside a step) against the events FMPy records.
    events = simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode", stop_time=1.5, output_interval=0.01,
                          output=["bounces"], record_events=True)
    theirs = [float(events["time"][i]) for i in range(1, len(events)) if events["bounces"][i] > events["bounces"][i - 1]]
    log = [json.loads(line) for line in (run / "node-ball.log.jsonl").read_text().splitlines()]
    ours = [e["t"] for e in log if e.get("event") == "fmu event" and e["kind"] == "state"]
    assert len(ours) == len(theirs) == 2
    assert max(abs(a - b) for a, b in zip(ours, theirs)) < 1e-6
    if fmi != "2.0":
        return
    # Euler: one step per macro step, as FMPy's Euler takes one per output interval; with maxStep
    # the node takes several (1 ms: h(0.01) = 1 - g·(1 ms)²·(0 + 1 + … + 9)).
    points = _simulate(fmus["me"], _ball(fmus["me"], solver="Euler"), 0.01, 1.5)
    ref = simulate_fmu(str(fmus["me"]), fmi_type="ModelExchange", solver="Euler", step_size=0.01, stop_time=1.5,
                       output_interval=0.01, output=["h", "v"], record_events=False)
    assert np.allclose([p["h"] for p in points], ref["h"], rtol=1e-12, atol=1e-12)
    points = _simulate(fmus["me"], _ball(fmus["me"], solver="Euler", maxStep=0.001), 0.01, 0.02)
    assert points[1]["h"] == pytest.approx(1 - 9.81 * 1e-6 * 45, abs=1e-12)


def test_inputs_time_events_and_termination_inside_a_macro_step(tmp_path, fmus):
    """A routed input holds the ball up (a = g); a kick at 0.505 s (a time event between two
    points) sends it up at 2 m/s from exactly then; a lower g lets it fall to its second bounce,
    where the FMU asks to end the run."""
    lift = {"nodeName": "lift", "UID": 2, "model": "gain", "parameters": {"k": 0.0, "b": 9.81},
            "input": ["u"], "output": ["y"]}
    cfg = write_project(tmp_path / "p.json", [
        lift, _ball(fmus["me"], input=["a"], parameters={"kick_at": 0.505, "kick": 2.0})],
        [{"from": "lift.y", "to": "ball.a"}], cosim={"stepSize": 0.01, "stopTime": 1.0})
    rows = read_rows(run_project(cfg, tmp_path / "runs"))
    t, h, v = column(rows, "t"), column(rows, "ball.h"), column(rows, "ball.v")
    assert t[51] == pytest.approx(0.51) and len(t) == 101
    for ti, hi, vi in zip(t, h, v):
        if ti <= 0.5:
            assert (hi, vi) == (1.0, 0.0)  # held up from the first step (the lift's output at t0 is routed)
        else:
            assert vi == pytest.approx(2.0, abs=1e-9) and hi == pytest.approx(1 + 2.0 * (ti - 0.505), abs=1e-9)
    # Termination at the second bounce: the run ends cleanly there, naming the FMU.
    cfg = write_project(tmp_path / "t.json", [_ball(fmus["me"], parameters={"max_bounces": 2})],
                        cosim={"stepSize": 0.01, "stopTime": 3.0})
    run = run_project(cfg, tmp_path / "runs-t")
    ended = meta(run)["ended_by"]
    bounce2 = math.sqrt(2 / 9.81) * (1 + 2 * 0.7)  # the second floor contact, analytically
    assert ended["node"] == "ball" and ended["t"] == pytest.approx(bounce2, abs=1e-4)
    assert "BallME.fmu asked to terminate the simulation" in ended["message"]
    # The last row is the contact the FMU ended at, as FMPy records it: the ball on the floor.
    last = read_rows(run)[-1]
    assert float(last["t"]) == ended["t"] and abs(float(last["ball.h"])) < 1e-6
    assert int(last["step"]) == ended["step"] == math.floor(bounce2 / 0.01) + 1


def test_an_fmu_with_both_interfaces_runs_as_co_simulation_unless_told(tmp_path, fmus):
    cosim = {"stepSize": 0.01, "stopTime": 1.0}
    cs = [p["h"] for p in _simulate(fmus["both"], _ball(fmus["both"]), 0.01, 1.0)]
    me = [p["h"] for p in _simulate(fmus["both"], _ball(fmus["both"], interface="ModelExchange"), 0.01, 1.0)]
    ref = simulate_fmu(str(fmus["both"]), fmi_type="ModelExchange", stop_time=1.0, output_interval=0.01, output=["h"],
                       record_events=False)
    assert np.allclose(me, ref["h"], rtol=1e-5, atol=1e-6)
    # The co-simulation interface's own Euler bounces at another time: a visible difference.
    assert max(abs(a - b) for a, b in zip(cs, me)) > 1e-3

    shown = hycosim("fmu", "inspect", str(fmus["both"]))
    assert shown.returncode == 0, shown.stderr
    assert "co-simulation, Model Exchange (the node integrates it)" in shown.stdout
    assert "needsCompletedIntegratorStep" in shown.stdout and "2, 1" in shown.stdout

    def refused(entry: dict) -> str:
        cfg = write_project(tmp_path / "bad.json", [entry], cosim=cosim)
        res = hycosim("validate", str(cfg))
        assert res.returncode == 2
        return res.stderr

    assert ("node 'ball': solver set, but BallBoth.fmu has a co-simulation interface, which the node uses "
            'unless told: add "interface": "ModelExchange"') in refused(_ball(fmus["both"], solver="Euler"))
    assert "BallME.fmu has no co-simulation interface (Model Exchange only)" in refused(
        _ball(fmus["me"], interface="CoSimulation"))
    assert "node 'ball' names interface but no 'fmu'" in refused(
        {"nodeName": "ball", "UID": 1, "model": "gain", "interface": "ModelExchange", "input": ["u"], "output": ["y"]})
    assert "runs its FMU as co-simulation, which integrates itself: relativeTolerance would do nothing" in refused(
        _ball(fmus["both"], interface="CoSimulation", relativeTolerance=1e-6))


@pytest.mark.parametrize("fmi", ["2.0", "3.0"])
def test_a_model_exchange_node_rolls_back_and_continues_from_its_serialised_state(tmp_path, fmus, fmi):
    """Get/set and serialised state carry the integrator's start and the announced time event:
    a step retried after a rollback, and a new instance restored from bytes, go on identically."""
    fmu = fmus["me" if fmi == "2.0" else "me3"]
    cfg = write_project(tmp_path / "p.json", [_ball(fmu, parameters={"kick_at": 0.3, "kick": 1.0})],
                        cosim={"stepSize": 0.05, "stopTime": 2.0})
    spec = load_project(cfg).project.node("ball")

    def made() -> FmuNode:
        node = FmuNode(spec, fmu)
        node.setup(NodeContext("ball", 1, [], list(spec.output), dict(spec.parameters), 0.05, 0.0, stop_time=2.0))
        return node

    a, b = made(), made()
    try:
        for k in range(4):  # to 0.2 s: the kick (0.3 s) still ahead, announced
            a.step(k * 0.05, 0.05, {})
        saved, data = a.get_state(), a.serialize_state()
        b.deserialize_state(data)
        first = []
        for k in range(4, 30):
            a.step(k * 0.05, 0.05, {})
            first.append(a.outputs())
        a.set_state(saved)
        for k in range(4, 30):
            a.step(k * 0.05, 0.05, {})
            b.step(k * 0.05, 0.05, {})
            assert a.outputs() == first[k - 4] == b.outputs()
        assert first[-1]["bounces"] >= 1 and max(o["v"] for o in first) > 0.5  # kicked and bounced
    finally:
        a.teardown()
        b.teardown()


def test_a_stiff_model_exchange_fmu_completes_with_cvode(tmp_path, fmus):
    """Van der Pol at mu = 1000 over more than a period (about 1614 s): BDF takes it in stride."""
    x0 = [p["x0"] for p in _simulate(fmus["vdp"], {"nodeName": "vdp", "UID": 1, "fmu": str(fmus["vdp"]),
                                                   "output": ["x0", "x1"]}, 10.0, 2000.0)]
    assert len(x0) == 201 and max(map(abs, x0)) < 2.1
    assert min(x0) < -1.9 and max(x0[100:]) > 1.9  # swung over to -2 and back to +2: a full period
    ref = simulate_fmu(str(fmus["vdp"]), fmi_type="ModelExchange", stop_time=2000.0, output_interval=10.0,
                       output=["x0"], record_events=False)
    assert np.allclose(x0, ref["x0"], atol=1e-3)
