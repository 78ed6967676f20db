"""FMI 3 periodic clocks: an input clock of a constant interval ticks at t0 + shift + k·interval,
each tick in event mode on the inputs of the step it falls in (at a point: before the step
from there; inside a step: the FMU's step is cut there). The runs equal an FMI 3 driver
written here against fmpy's FMU3Slave from the FMI standard's steps, to the bit; they are the
same in process, and after a node killed mid-run is restored from a checkpoint. Clocks hycosim
does not tick are refused by name (tests/test_fmi3.py)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave
from hypothesis import given
from hypothesis import strategies as st

from hycosim.fmi.loader import MAX_TICKS, Clock, clock_ticks, clocks_of
from tests.fmi3_fmus import build
from tests.helpers import column, hycosim, meta, read_rows, run_killing, run_project, write_project


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    return build(tmp_path_factory.mktemp("clocks"))


def _project(tmp_path, fmu, step, stop, name="ck", cosim=None, **changes):
    """ss (the clocked state-space FMU) with its array input u from a Python node's ramp and
    its input g from that ramp's first element, its sum s into a gain: the inputs change at
    every point."""
    ss = {"nodeName": "ss", "UID": 1, "fmu": str(fmu), "input": [{"name": "u", "shape": [2]}, "g"],
          "output": ["s", "held", "ticks"]}
    vec = {"nodeName": "vec", "UID": 2, "model": "tests.nodes:Vector", "output": [{"name": "v", "shape": [2]}, "total"]}
    g = {"nodeName": "g", "UID": 3, "model": "gain", "input": ["u"], "output": ["y"]}
    nodes = [ss, vec, g]
    for key, value in changes.items():
        node, _, field = key.partition("__")
        next(n for n in nodes if n["nodeName"] == node)[field] = value
    links = [{"from": "vec.v", "to": "ss.u"}, {"from": "vec.v[0]", "to": "ss.g", "factor": -0.5},
             {"from": "ss.s", "to": "g.u"}]
    return write_project(tmp_path / f"{name}.json", nodes, links, name=name,
                         cosim={"stepSize": step, "stopTime": stop, **(cosim or {})})


def _driven_by_the_standard(fmu, rows, interval, shift):
    """The FMU stepped on the recorded grid and inputs by fmpy's FMU3Slave as FMI 3.0 says a
    clocked co-simulation FMU is imported (eventModeUsed; Event Mode after initialisation;
    at a tick: fmi3EnterEventMode, fmi3SetClock, fmi3UpdateDiscreteStates, fmi3EnterStepMode),
    each tick found by counting periods on its own; its s, held and ticks at every point."""
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU3Slave(guid=md.instantiationToken, unzipDirectory=extract(str(fmu)),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="ref")
    slave.instantiate(eventModeUsed=True)
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    slave.updateDiscreteStates()
    slave.enterStepMode()

    def read():
        return [slave.getFloat64([vr["s"]])[0], slave.getFloat64([vr["held"]])[0], slave.getFloat64([vr["ticks"]])[0]]

    times = column(rows, "t")
    got = [read()]
    n = 0  # the next tick's count
    for k in range(len(rows) - 1):
        t, end = times[k], times[k + 1]
        slave.setFloat64([vr["u"]], [float(rows[k]["ss.u[0]"]), float(rows[k]["ss.u[1]"])])
        slave.setFloat64([vr["g"]], [float(rows[k]["ss.g"])])
        now = t
        while shift + n * interval < end - 1e-9:
            tick = shift + n * interval
            if tick > now + 1e-9:
                slave.doStep(currentCommunicationPoint=now, communicationStepSize=tick - now)
                now = tick
            slave.enterEventMode()
            slave.setClock([vr["tick"]], [True])
            slave.updateDiscreteStates()
            slave.enterStepMode()
            n += 1
        slave.doStep(currentCommunicationPoint=now, communicationStepSize=end - now)
        got.append(read())
    slave.terminate()
    slave.freeInstance()
    return got


@pytest.mark.parametrize("kind, step, interval, shift, cosim", [
    ("periodic", 0.05, 0.1, 0.0, None),  # every other point is a tick
    ("shifted", 0.04, 0.1, 0.05, None),  # ticks inside steps: the FMU's step is cut there
    # each step taken again from its saved state until the inputs settle: a tick is retaken with it
    ("shifted", 0.04, 0.1, 0.05, {"iterate": {"tolerance": 1e-12, "maxIterations": 20}}),
], ids=["ticks on points", "ticks inside steps", "iterated steps"])
def test_a_periodic_clock_ticks_as_the_standard_drives_it(tmp_path, fmus, kind, step, interval, shift, cosim):
    run = run_project(_project(tmp_path, fmus[kind], step, 1.0, cosim=cosim), tmp_path / "runs")
    rows = read_rows(run)
    if cosim:
        assert sum(int(r["takes"]) for r in read_rows(run, "timing.csv")) > len(rows)  # steps were retaken
    want = _driven_by_the_standard(fmus[kind], rows, interval, shift)
    assert [[float(r["ss.s"]), float(r["ss.held"]), float(r["ss.ticks"])] for r in rows] == want  # to the bit
    times = column(rows, "t")
    # A point's count is of the ticks before it; one at the point itself comes with the step from there.
    assert column(rows, "ss.ticks") == [float(sum(1 for j in range(20) if shift + j * interval < t - 1e-9))
                                        for t in times]
    if kind == "periodic":
        # held is s as a tick leaves it; s at a point is read before the step's inputs are set,
        # so held after the tick at point j differs from s there by D·(u_j − u_(j−1)).
        held, s = column(rows, "ss.held"), column(rows, "ss.s")
        for k in range(3, len(rows), 2):
            j = k - 1
            du = [float(rows[j][f"ss.u[{i}]"]) - float(rows[j - 1][f"ss.u[{i}]"]) for i in (0, 1)]
            assert math.isclose(held[k], s[j] + 0.1 * (du[0] + du[1]), rel_tol=1e-12)


def test_clocked_runs_are_the_same_in_process_and_restored_from_checkpoints(tmp_path, fmus):
    expected = (run_project(_project(tmp_path, fmus["shifted"], 0.04, 2.0), tmp_path / "a") / "values.csv").read_bytes()
    res = hycosim("run", str(_project(tmp_path, fmus["shifted"], 0.04, 2.0)), "--in-process",
                  "--runs-dir", str(tmp_path / "b"), "--no-progress")
    assert res.returncode == 0, res.stderr
    assert (next((tmp_path / "b").iterdir()) / "values.csv").read_bytes() == expected
    # The state a checkpoint holds is between ticks: a restored FMU ticks where the first would have.
    cfg = _project(tmp_path, fmus["shifted"], 0.04, 2.0, name="ck", cosim={"checkpointEvery": 0.2,
                                                                            "attachTimeout": 20.0},
                   g__parameters={"work_s": 0.02})  # 50 steps of 20 ms: the kill lands mid-run
    code, err = run_killing(cfg, tmp_path / "c", [("node ss", 12)], "--restarts", "2")
    assert code == 0, err
    run = next((tmp_path / "c").iterdir())
    assert [r["node"] for r in meta(run)["recoveries"]] == ["ss"]
    assert (run / "values.csv").read_bytes() == expected


@given(interval=st.floats(1e-3, 2.0), shift=st.floats(0.0, 1.0), t0=st.floats(-10.0, 10.0),
       cuts=st.lists(st.floats(1e-3, 0.5), min_size=1, max_size=40), second=st.booleans())
def test_every_tick_falls_in_exactly_one_step_whatever_the_steps(interval, shift, t0, cuts, second):
    """Steps of drawn lengths from t0: each tick at t0 + shift + k·interval before the end is
    handed to exactly one step, the one whose start it is at or after, in order; two clocks of
    the same interval tick together in one event."""
    clocks = [Clock("tick", "input", "periodic", interval, shift, vr=20)]
    if second:
        clocks.append(Clock("tock", "input", "periodic", interval, shift, vr=21))
    points = [t0]
    for c in cuts:
        points.append(points[-1] + c)
    handed = []
    for t, end in zip(points, points[1:]):
        for at, vrs in clock_ticks(clocks, t0, t, end):
            assert t - 1e-9 * max(1.0, abs(end)) <= at < end
            assert vrs == ([20, 21] if second else [20])
            handed.append(at)
    tol = 1e-9 * max(1.0, abs(points[-1]))
    want = [t0 + shift + k * interval for k in range(int((points[-1] - t0) / interval) + 2)
            if t0 + shift + k * interval < points[-1] - tol]
    assert handed == want


_numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30),
                     st.text(max_size=6), st.just("1e-300"), st.just("nan"), st.just("-inf"))
_attributes = st.fixed_dictionaries({}, optional={
    name: _numbers.map(str) for name in ("intervalDecimal", "shiftDecimal", "intervalCounter", "shiftCounter",
                                         "resolution")})


@given(attributes=_attributes, t0=st.floats(-100, 100), h=st.floats(1e-3, 10.0))
def test_a_clock_as_any_model_description_declares_it_is_refused_by_name_or_ticks_a_bounded_step(
        tmp_path_factory, attributes, t0, h):
    """Whatever interval, shift, counters and resolution an FMU's model description gives an
    input clock of a constant interval (numbers, huge or tiny, text, inf, nan): hycosim either
    refuses it with a reason, or hands each step a bounded list of ticks inside it, or says by
    name that it ticks too often for a step; nothing else is raised and nothing hangs."""
    folder = tmp_path_factory.mktemp("md")
    xml = "".join(f' {k}="{v}"' for k, v in attributes.items() if '"' not in v and "<" not in v and "&" not in v)
    (folder / "modelDescription.xml").write_text(
        f'<fmiModelDescription><ModelVariables><Clock name="tick" valueReference="20"{xml}/>'
        "</ModelVariables></fmiModelDescription>")
    md = SimpleNamespace(modelVariables=[SimpleNamespace(name="tick", type="Clock", causality="input",
                                                         intervalVariability="constant", valueReference=20)])
    (clock,) = clocks_of(md, folder)
    if clock.refusal() is not None:
        assert clock.refusal()
        with pytest.raises(ValueError, match="clock 'tick' is not ticked by hycosim"):
            clock_ticks([clock], t0, t0, t0 + h)
        return
    try:
        ticks = clock_ticks([clock], t0, t0, t0 + h)
    except ValueError as exc:
        assert f"would tick more than {MAX_TICKS:,} times" in str(exc)
        return
    assert len(ticks) <= MAX_TICKS + 1
    assert all(math.isfinite(at) and t0 - 1e-6 <= at < t0 + h for at, _ in ticks)
