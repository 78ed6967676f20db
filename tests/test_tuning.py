"""Tunable parameters changed during a run: a scenario's ``parameter`` action and
``sim.set_parameter``, sent to the node as TUNE before the step they apply from, recorded,
and sent again as in force after a rollback to a checkpoint."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from hypothesis import given, settings

import hycosim
from hycosim.core import frames
from hycosim.master.report import read_scenario
from tests.helpers import column, hycosim as cli, meta, read_rows, run_killing, run_project, write_project
from tests.wire_strategies import frame_arrays

NODES = [{"nodeName": "ramp", "UID": 1, "model": "ramp", "output": ["y", "v"]},
         {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]}]
LINKS = [{"from": "ramp.y", "to": "g.u"}]


def _project(tmp_path: Path, scenario: list | None = None, name: str = "tune", **cosim) -> Path:
    return write_project(tmp_path / f"{name}.json", NODES, LINKS, name=name,
                         cosim={"stepSize": 0.1, "stopTime": 2.0, **cosim}, scenario=scenario or [])


def _gain_follows(rows: list[dict], k_at) -> None:
    """g.y at point j + 1 is k·u at point j, k the value in force at point j."""
    u, y, t = column(rows, "g.u"), column(rows, "g.y"), column(rows, "t")
    for j in range(len(rows) - 1):
        assert y[j + 1] == pytest.approx(k_at(t[j]) * u[j], abs=1e-12), (j, t[j])


@pytest.mark.parametrize("mode", ["--in-process", "--processes"])
def test_a_scenario_parameter_action_changes_the_gain_from_its_point_on(tmp_path, mode):
    cfg = _project(tmp_path, [{"t": 0.5, "parameter": "g.k", "value": 3.0},
                              {"t": 1.2, "parameter": "g.k", "value": -1}])  # an int for a float parameter
    res = cli("run", str(cfg), mode, "--no-progress", "--runs-dir", str(tmp_path / "runs"))
    assert res.returncode == 0, res.stderr
    run = next((tmp_path / "runs").iterdir())
    _gain_follows(read_rows(run), lambda t: 1.0 if t < 0.5 - 1e-9 else 3.0 if t < 1.2 - 1e-9 else -1.0)
    said = [(r["scenario"], r["target"], r["value"], r["step"]) for r in read_scenario(run)]
    assert said == [("parameter", "g.k", 3.0, 5), ("parameter", "g.k", -1, 12)]


@pytest.mark.parametrize("distributed", [False, True])
def test_set_parameter_from_python_takes_effect_at_the_next_step_and_refuses_what_is_not_tunable(tmp_path, distributed):
    doc = json.loads(_project(tmp_path).read_text())
    with hycosim.open(doc, runs_dir=tmp_path / "runs", distributed=distributed) as sim:
        sim.run_until(0.3)
        sim.set_parameter("g.b", 10.0)
        for bad, says in ((("g.q", 1.0), "declares no tunable parameter 'q' (its tunable parameters: b, k)"),
                          (("ramp.a", 1.0), "declares no tunable parameter 'a'"),
                          (("nobody.k", 1.0), "no parameter of a stepping node"),
                          (("g.k", "x"), "g.k is a float, not 'x'"), (("g.k", math.nan), "not nan"),
                          (("g.k", [1.0]), "not [1.0]")):
            with pytest.raises(hycosim.ParameterError, match=says.replace("(", r"\(").replace(")", r"\)")
                               .replace("[", r"\[").replace("]", r"\]")):
                sim.set_parameter(*bad)
        sim.run_until(1.0)
        sim.set_parameter("g.b", 0.0)
    rows = read_rows(sim.run_dir)
    u, y = column(rows, "g.u"), column(rows, "g.y")
    assert all(y[j + 1] == pytest.approx(u[j] + (10.0 if 3 <= j < 10 else 0.0)) for j in range(len(rows) - 1))
    assert [(r["target"], r["value"]) for r in read_scenario(sim.run_dir)] == [("g.b", 10.0), ("g.b", 0.0)]
    # Kept where a resumed run reads its scenario back.
    assert meta(sim.run_dir)["scenario"] == [{"t": pytest.approx(0.3), "parameter": "g.b", "value": 10.0},
                                            {"t": pytest.approx(1.0), "parameter": "g.b", "value": 0.0}]


def test_a_tuned_parameter_is_in_force_again_after_a_node_is_killed_and_the_run_restored(tmp_path):
    """The gain's process is killed after the first change: its new process starts with k = 1,
    and the run, back at a checkpoint after the change, sends it k = 3 again."""
    nodes = [NODES[0], {**NODES[1], "parameters": {"work_s": 0.004}}]
    scenario = [{"t": 1.0, "parameter": "g.k", "value": 3.0}, {"t": 3.0, "parameter": "g.k", "value": 0.5}]
    cfg = write_project(tmp_path / "slow.json", nodes, LINKS, name="slow", scenario=scenario,
                        cosim={"stepSize": 0.01, "stopTime": 4.0, "checkpointEvery": 0.5, "attachTimeout": 20.0})
    reference = run_project(cfg, tmp_path / "reference")
    code, err = run_killing(cfg, tmp_path / "runs", [("node g", 230)], "--restarts", "2")
    assert code == 0, err
    run = next((tmp_path / "runs").iterdir())
    # Restored between the two changes (k = 3 from step 100, k = 0.5 from step 300), wherever the
    # kill landed after step 230 on a loaded machine: the run must send k = 3 again.
    assert [r["node"] for r in meta(run)["recoveries"]] == ["g"] and 100 < meta(run)["recoveries"][0]["restored"] < 300
    assert (run / "values.csv").read_bytes() == (reference / "values.csv").read_bytes()
    _gain_follows(read_rows(run), lambda t: 1.0 if t < 1.0 - 1e-9 else 3.0 if t < 3.0 - 1e-9 else 0.5)


def test_an_fmus_tunable_parameter_set_before_it_matters_gives_the_run_it_would_start_with(tmp_path):
    from tests.me_fmus import build_me_fmus

    (tmp_path / "fmus").mkdir()
    fmu = build_me_fmus(tmp_path / "fmus")["both"]  # the ball, as co-simulation: e (restitution) tunable
    ball = {"nodeName": "ball", "UID": 1, "fmu": str(fmu), "output": ["h", "v"]}
    cosim = {"stepSize": 0.01, "stopTime": 1.5}
    tuned = write_project(tmp_path / "tuned.json", [ball], name="tuned", cosim=cosim,
                          scenario=[{"t": 0.2, "parameter": "ball.e", "value": 0.3}])
    started = write_project(tmp_path / "started.json", [{**ball, "parameters": {"e": 0.3}}], name="started",
                            cosim=cosim)
    default = write_project(tmp_path / "default.json", [ball], name="default", cosim=cosim)
    res = cli("validate", str(tuned))
    assert res.returncode == 0, res.stdout + res.stderr
    rows = [read_rows(run_project(cfg, tmp_path / cfg.stem)) for cfg in (tuned, started, default)]
    assert [r["ball.v"] for r in rows[0]] == [r["ball.v"] for r in rows[1]]  # the first bounce is at 0.45 s
    assert [r["ball.v"] for r in rows[0]] != [r["ball.v"] for r in rows[2]]
    # What the FMU does not declare tunable is named by validate and run, before anything starts.
    for name, says in (("g", "'g' of BallBoth.fmu is parameter, fixed"), ("nope", "has no variable 'nope'")):
        bad = write_project(tmp_path / "bad.json", [ball], name="bad", cosim=cosim,
                            scenario=[{"t": 0.2, "parameter": f"ball.{name}", "value": 1.0}])
        for command in (("validate", str(bad)), ("run", str(bad), "--no-progress", "--runs-dir", str(tmp_path / "r"))):
            res = cli(*command)
            assert res.returncode == 2 and "scenario[0].parameter" in res.stderr and says in res.stderr, res.stderr
        assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("action, says", [
    ({"t": 0.5, "parameter": "nobody.k", "value": 1.0}, "scenario[0].parameter"),
    ({"t": 0.5, "parameter": "g.k", "value": [1.0]}, "a parameter action gives a 'value'"),
    ({"t": 0.5, "parameter": "g.k", "ramp": {"to": 1.0, "duration": 1.0}}, "a parameter action gives a 'value'"),
    ({"t": 0.5, "parameter": "g.k", "value": 1.0, "override": "g.u"}, "one of them"),
    ({"t": 9.0, "parameter": "g.k", "value": 1.0}, "outside the run"),
])
def test_a_parameter_action_that_cannot_be_taken_is_named_by_validate(tmp_path, action, says):
    res = cli("validate", str(_project(tmp_path, [action])))
    assert res.returncode == 2 and says in res.stdout + res.stderr and "Traceback" not in res.stderr, res.stderr


def test_a_parameter_the_python_model_does_not_declare_tunable_stops_the_run_before_its_first_step(tmp_path):
    cfg = _project(tmp_path, [{"t": 0.5, "parameter": "g.q", "value": 1.0}])
    res = cli("run", str(cfg), "--in-process", "--no-progress", "--runs-dir", str(tmp_path / "runs"))
    assert res.returncode == 3 and "g.q, which node 'g' does not declare tunable (its tunable parameters: b, k)" \
        in res.stderr, res.stderr
    assert len(read_rows(next((tmp_path / "runs").iterdir()))) <= 1


_TUNABLE = {"k": 1.0, "i": 2, "on": True, "s": "x"}


@settings(max_examples=300)
@given(frame_arrays([frames.TUNE]).map(frames.msgpack.packb))
def test_a_node_takes_a_tune_only_of_its_tunable_parameters_each_of_its_type(payload):
    from hycosim.core.schema import CoSimulation, Node as NodeSpec
    from hycosim.node.receiving import Receiver

    spec = NodeSpec.model_validate({"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]})
    receiver = Receiver(spec, CoSimulation(), "tcp/127.0.0.1:1", None, None, lambda: 0, {"free": ()})
    receiver.tunable = _TUNABLE
    try:
        frame = receiver.accept(False, payload)
    except frames.FrameError:
        return
    if frame is None:
        return  # another node's
    assert frame.kind == frames.TUNE and frame.node == "g" and 0 <= frame.step < frames.MAX_STEP
    assert math.isfinite(frame.t) and frame.values
    for name, value in frame.values.items():
        assert name in _TUNABLE and frames.tunable_value(value)
        assert type(value) is type(_TUNABLE[name]) or (type(_TUNABLE[name]) is float and type(value) is int)
