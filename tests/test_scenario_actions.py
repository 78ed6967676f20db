"""Scenarios: inputs overridden in time (a value, a ramp), released; from the project, from
--scenario FILE and from Python; recorded, checked before anything runs, and held through a
node's restart and a server's resume as they were."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

import hycosim
from hycosim.core.config import ConfigError, load_project
import msgpack

from hycosim.core.scenario_checks import load_scenario, value_problem
from hycosim.master.report import read_events, read_scenario
from tests.helpers import hycosim as cli, meta, read_rows, run_killing, run_project, write_project

ACTIONS = [{"t": 0.3, "override": "g.u", "value": 5.0},
           {"t": 0.5, "override": "g.u", "ramp": {"to": 1.0, "duration": 0.2}},
           {"t": 0.8, "release": "g.u"}]


def _chain(tmp_path: Path, scenario: list | None = None, name: str = "p.json") -> Path:
    extra = {"scenario": scenario} if scenario is not None else {}
    return write_project(tmp_path / name, [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "parameters": {"k": 2.0}, "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.1, "stopTime": 1.0}, name="sc", **extra)


def test_a_scenario_overrides_ramps_and_releases_an_input_as_written(tmp_path):
    run = run_project(_chain(tmp_path, ACTIONS), tmp_path / "runs")
    rows = read_rows(run)
    seen = {round(float(r["t"]), 6): float(r["g.u"]) for r in rows}
    expected = {0.0: 0.0, 0.1: 0.1, 0.2: 0.2, 0.3: 5.0, 0.4: 5.0, 0.5: 5.0, 0.6: 3.0, 0.7: 1.0, 0.8: 0.8, 0.9: 0.9,
                1.0: 1.0}
    assert seen == pytest.approx(expected, abs=1e-12)
    # The node stepped on what it saw: the gain's output a step later is twice it.
    assert [float(r["g.y"]) for r in rows[4:7]] == pytest.approx([10.0, 10.0, 10.0])
    took = read_scenario(run)
    assert [(e["scenario"], e["target"], e["step"]) for e in took] == [("override", "g.u", 3), ("override", "g.u", 5),
                                                                       ("release", "g.u", 8)]
    assert read_events(run) == []  # no mode switch: the records are told apart
    res = cli("report", str(run))
    assert res.returncode == 0, res.stderr


def test_the_same_actions_from_a_file_from_python_and_in_one_process_record_the_same(tmp_path):
    project_run = run_project(_chain(tmp_path, ACTIONS), tmp_path / "project")
    plain = _chain(tmp_path, None, "plain.json")
    (tmp_path / "scen.json").write_text(json.dumps({"scenario": ACTIONS}))
    for mode in ("--processes", "--in-process"):
        res = cli("run", str(plain), "--scenario", str(tmp_path / "scen.json"), mode, "--no-progress",
                  "--runs-dir", str(tmp_path / mode))
        assert res.returncode == 0, res.stderr
        run = next((tmp_path / mode).iterdir())
        assert (run / "values.csv").read_bytes() == (project_run / "values.csv").read_bytes(), mode
        assert meta(run)["scenario"][1]["ramp"] == {"to": 1.0, "duration": 0.2}
    with hycosim.open(plain, runs_dir=tmp_path / "api") as sim:
        sim.run_until(0.3)
        sim.override("g.u", 5.0)
        assert sim.get("g.u") == 5.0  # the step it takes next is on it
        sim.run_until(0.6)
        sim.override("g.u", 3.0)
        sim.step()
        sim.override("g.u", 1.0)
        sim.run_until(0.8)
        sim.release("g.u")
        assert sim.get("g.u") == pytest.approx(0.8)
        sim.run_until(1.0)
    rows, reference = read_rows(sim.run_dir), read_rows(project_run)
    for port in ("g.u", "g.y"):  # the ramp's points given as values (3.0 where it computed 2.9999999999999982)
        assert [float(r[port]) for r in rows] == pytest.approx([float(r[port]) for r in reference], abs=1e-12)
    assert [e["t_action"] for e in read_scenario(sim.run_dir)] == pytest.approx([0.3, 0.6, 0.7, 0.8])


@pytest.mark.parametrize("action, where, says", [
    ({"t": 5.0, "override": "g.u", "value": 1.0}, "[0].t", "outside the run"),
    ({"t": 0.1, "override": "g.x", "value": 1.0}, "[0].override", "'g.x' is no input a link feeds"),
    ({"t": 0.1, "override": "clock.y", "value": 1.0}, "[0].override", "no input a link feeds"),
    ({"t": 0.1, "override": "g.u", "value": "high"}, "[0].value", "g.u takes a finite number, not 'high'"),
    ({"t": 0.1, "override": "g.u", "value": True}, "[0].value", "g.u takes a finite number, not True"),
    ({"t": 0.1, "override": "g.u", "value": 10 ** 400}, "[0].value", "g.u takes a finite number"),
    ({"t": 0.1, "override": "g.u", "ramp": {"to": 10 ** 400, "duration": 1.0}}, "[0].ramp.to", "not a finite number"),
    ({"t": 0.1, "release": "g.u"}, "[0].release", "not overridden before"),
    ({"t": 0.1, "override": "g.u"}, "[0]", "an override gives a 'value' or a 'ramp'"),
    ({"t": 0.1, "override": "g.u", "ramp": {"to": 1.0, "duration": 0}}, "[0].ramp.duration", "greater than 0"),
    ({"t": 0.1, "override": "g.u", "value": 1.0, "when": 3}, "[0].when", "unknown key"),
])
def test_a_scenario_action_that_cannot_be_taken_is_named_before_anything_runs(tmp_path, action, where, says):
    plain = _chain(tmp_path, None)
    (tmp_path / "scen.json").write_text(json.dumps([action]))
    res = cli("run", str(plain), "--scenario", str(tmp_path / "scen.json"), "--runs-dir", str(tmp_path / "runs"))
    assert res.returncode == 2 and f"scen.json: {where}" in res.stderr and says in res.stderr, res.stderr
    assert "Traceback" not in res.stderr and not (tmp_path / "runs").exists()
    project = _chain(tmp_path, [action], "in-project.json")  # the same in the project file
    res = cli("validate", str(project))
    assert res.returncode == 2 and f"scenario{where}" in res.stderr and says in res.stderr, res.stderr


_NUMBER = st.integers(-10, 10) | st.integers() | st.sampled_from([2 ** 31, -2 ** 31 - 1, 10 ** 400]) | st.floats()
_JSON = st.recursive(st.none() | st.booleans() | _NUMBER | st.text(max_size=6),
                     lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3),
                     max_leaves=8)
_ACTION = st.fixed_dictionaries({}, optional={
    "t": st.floats(allow_nan=True, allow_infinity=True) | _JSON,
    "override": st.sampled_from(["g.u", "clock.y", "g", "sink.n", "sink.b", "sink.a"]) | _JSON,
    "release": st.sampled_from(["g.u", "sink.n", "x.y"]) | _JSON,
    "value": _JSON | st.lists(_NUMBER, min_size=2, max_size=2),
    "ramp": st.fixed_dictionaries({}, optional={"to": _NUMBER | _JSON, "duration": _NUMBER | _JSON,
                                                "from": _NUMBER | _JSON}) | _JSON,
    "description": _JSON})


def _typed(folder: Path) -> Path:
    """Inputs of every kind a link feeds: Real, an Integer, a Boolean, a Real array."""
    return write_project(folder / "typed.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
        {"nodeName": "src", "UID": 3, "model": "ramp",
         "output": [{"name": "n", "type": "Integer"}, {"name": "b", "type": "Boolean"}, {"name": "a", "shape": [2]}]},
        {"nodeName": "sink", "UID": 4, "model": "gain",
         "input": [{"name": "n", "type": "Integer"}, {"name": "b", "type": "Boolean"}, {"name": "a", "shape": [2]}],
         "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}, {"from": "src", "to": "sink", "pairs": [["n", "n"], ["b", "b"], ["a", "a"]]}],
        cosim={"stepSize": 0.1, "stopTime": 1.0}, name="typed")


def test_a_rollback_to_the_point_of_an_action_records_it_again_once(tmp_path):
    """A point's checkpoint is taken before its actions are recorded: a rollback to it must
    record them again (a kill that restored the checkpoint at an action's time lost its line)."""
    from hycosim.master.scenario import Scenario

    loaded = load_project(_chain(tmp_path, ACTIONS))
    scenario = Scenario(loaded.project, loaded.routes, loaded.project.scenario)
    assert [e["t_action"] for e in scenario.taking_effect(6, 0.6)] == [0.3, 0.5]
    scenario.rewind(0.5)  # back to the checkpoint at 0.5, the ramp's point
    assert [e["t_action"] for e in scenario.taking_effect(5, 0.5)] == [0.5]
    scenario.rewind(0.4)
    assert [e["t_action"] for e in scenario.taking_effect(4, 0.4)] == []
    assert [e["t_action"] for e in scenario.taking_effect(9, 0.9)] == [0.5, 0.8]


@given(doc=st.lists(_ACTION, max_size=4) | st.fixed_dictionaries({"scenario": st.lists(_ACTION, max_size=3)}) | _JSON)
def test_a_scenario_file_is_taken_or_named_whatever_it_holds(tmp_path_factory, doc):
    from hycosim.master.scenario import Scenario, from_meta

    folder = tmp_path_factory.mktemp("scen")
    loaded = load_project(_typed(folder))
    path = folder / "scen.json"
    path.write_text(json.dumps(doc))
    try:
        actions = load_scenario(path, loaded.project, loaded.routes)
    except ConfigError as exc:
        assert exc.issues and all(i.path and i.message for i in exc.issues)
    else:
        assert all(0.0 <= a.t <= 1.0 and a.target in ("g.u", "sink.n", "sink.b", "sink.a") for a in actions)
        # What was taken can be run: the values at any point fit their ports and the wire.
        scenario = Scenario(loaded.project, loaded.routes, actions)
        for t in (0.0, 0.35, 1.0):
            for node, pins in scenario.pins_at(t).items():
                for i, value in pins:
                    port = loaded.project.node(node).input[i]
                    assert value_problem(port, value) is None, (port.name, value)
                    msgpack.packb(value)
        assert from_meta([a.model_dump(by_alias=True, exclude_none=True) for a in actions], loaded.project,
                         loaded.routes) == actions  # what a resumed run reads back of it
    # Whatever a meta.json holds where the scenario was kept: taken whole, or refused in words.
    try:
        from_meta(doc, loaded.project, loaded.routes)
    except ValueError as exc:
        assert str(exc).startswith("its scenario cannot be")


def _slow_chain(tmp_path: Path) -> Path:
    """A pendulum and gains with checkpoints, slow enough per step for a kill to land mid-run."""
    nodes = [
        {"nodeName": "pend", "UID": 1, "model": "pendulum", "parameters": {"theta0": 0.5}, "input": ["theta_in"],
         "output": ["theta", "omega"]},
        {"nodeName": "g1", "UID": 2, "model": "gain", "parameters": {"k": 2.0}, "input": ["u"], "output": ["y"]},
        {"nodeName": "g2", "UID": 3, "model": "gain", "parameters": {"k": 0.5, "work_s": 0.003}, "input": ["u"],
         "output": ["y"]},
    ]
    links = [{"from": "pend.theta", "to": "g1.u"}, {"from": "g1.y", "to": "g2.u"},
             {"from": "pend.omega", "to": "pend.theta_in"}]
    scenario = [{"t": 1.0, "override": "g2.u", "value": 0.25},
                {"t": 2.0, "override": "g2.u", "ramp": {"to": -1.0, "duration": 1.5}},
                {"t": 3.3, "release": "g2.u"}]
    return write_project(tmp_path / "p.json", nodes, links, name="kept", scenario=scenario,
                         cosim={"stepSize": 0.01, "stopTime": 4.0, "checkpointEvery": 0.5, "attachTimeout": 20.0})


def test_overrides_hold_through_a_node_restart_and_a_server_resume(tmp_path):
    cfg = _slow_chain(tmp_path)
    reference = run_project(cfg, tmp_path / "reference")
    code, err = run_killing(cfg, tmp_path / "restarted", [("node g2", 170), ("node g1", 260)], "--restarts", "2")
    assert code == 0, err
    run = next((tmp_path / "restarted").iterdir())
    assert (run / "values.csv").read_bytes() == (reference / "values.csv").read_bytes()
    assert [r["cause"] for r in meta(run)["recoveries"]] == ["restarted", "restarted"]
    assert read_scenario(run) == read_scenario(reference)  # each action recorded once, the rollback's cut
    code, err = run_killing(cfg, tmp_path / "resumed", [("server", 240)])
    assert code == 3, err
    run = next((tmp_path / "resumed").iterdir())
    res = cli("run", str(cfg), "--resume", str(run), "--no-progress", timeout=120)
    assert res.returncode == 0, res.stderr
    assert (run / "values.csv").read_bytes() == (reference / "values.csv").read_bytes()
    assert read_scenario(run) == read_scenario(reference)
