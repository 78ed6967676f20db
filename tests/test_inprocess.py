"""``hycosim run --in-process``: the master and every node in one process record what the
distributed run (server and nodes as processes over Zenoh on loopback) records, byte for byte."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hycosim.scenario.scene_fmus import build_scene_fmus
from hycosim.core import frames
from hycosim.core.config import load_project
from hycosim.transport.local_bus import LocalBus
from tests.me_fmus import build_me_fmus
from tests.helpers import REPO, hycosim, meta, read_rows, run_project, write_project
from tests.wire_strategies import payloads

sys.path.insert(0, str(REPO / "benchmarks"))
import _small_fmus  # noqa: E402
import accuracy  # noqa: E402

# Measured, not computed: the policy's inference time differs from run to run in any mode.
WALL_CLOCK_COLUMNS = {"policy.infer_ms"}


def _run_both(cfg: Path, tmp: Path, *extra: str) -> tuple[Path, Path]:
    """The project run in processes and in process; both run directories."""
    distributed = run_project(cfg, tmp / f"{cfg.stem}-processes")
    res = hycosim("run", str(cfg), "--in-process", "--runs-dir", str(tmp / f"{cfg.stem}-inprocess"), "--no-progress",
                  *extra, timeout=300)
    assert res.returncode == 0, res.stderr
    inprocess = next((tmp / f"{cfg.stem}-inprocess").iterdir())
    assert meta(inprocess)["endpoint"] == "inprocess" and meta(distributed)["endpoint"] != "inprocess"
    return distributed, inprocess


def _same_values(a: Path, b: Path) -> None:
    x, y = (a / "values.csv").read_bytes(), (b / "values.csv").read_bytes()
    if x == y:
        return
    rows_a, rows_b = read_rows(a), read_rows(b)
    assert len(rows_a) == len(rows_b) and set(rows_a[0]) & WALL_CLOCK_COLUMNS, "values.csv differ"
    for ra, rb in zip(rows_a, rows_b):
        assert {k: v for k, v in ra.items() if k not in WALL_CLOCK_COLUMNS} == \
            {k: v for k, v in rb.items() if k not in WALL_CLOCK_COLUMNS}


@pytest.fixture(scope="module")
def mass_fmu(tmp_path_factory) -> Path:
    return accuracy.build_mass_fmu(tmp_path_factory.mktemp("mass"))


@pytest.mark.parametrize("scheme", list(accuracy.SCHEMES))
def test_the_accuracy_benchmarks_couplings_record_the_same_values_in_process(mass_fmu, tmp_path, scheme):
    cfg = accuracy.oscillator(tmp_path, mass_fmu, scheme, 0.01, 0.3, "three")
    distributed, inprocess = _run_both(cfg, tmp_path)
    _same_values(distributed, inprocess)
    assert len(read_rows(inprocess)) > 30  # start-up steps of interpolation add short ones
    # Steps are calls in process, retakes too, save where inputs follow polynomials (slopes go by frame).
    assert meta(inprocess)["releases"] == ("frames (interpolated inputs)" if "interpolated" in scheme
                                           else "calls (in process)")


def test_step_control_multi_rate_batches_and_a_located_event_record_the_same_values_in_process(mass_fmu, tmp_path):
    at_rest = {"m1": {"x": 0.0, "c": accuracy.DAMPING, **accuracy.PULSE}, "m2": {"xl": 0.0, "c": accuracy.DAMPING}}
    controlled = accuracy.oscillator(tmp_path, mass_fmu, "jacobi", 0.01, 1.1, **at_rest, cosim={
        "stepControl": {"tolerance": 1e-4, "minStep": 1e-4, "maxStep": 0.2}})
    chain = accuracy.rates_chain(tmp_path, 0.2, rates=True, batch=True)
    # A Model Exchange FMU (a bouncing ball) whose impact is located by rollback and bisection.
    ball = build_me_fmus(tmp_path)["me"]
    located = write_project(tmp_path / "ball.json", [
        {"nodeName": "ball", "UID": 1, "fmu": str(ball),
         "output": ["h", "v", {"name": "bounces", "type": "Integer"}]}], events=[
        {"name": "bounced", "when": "ball.bounces >= 1", "drives": "ball", "until": "ball.bounces >= 2"}],
        cosim={"stepSize": 0.05, "stopTime": 0.8, "eventTolerance": 1e-4})
    for cfg in (controlled, chain, located):
        distributed, inprocess = _run_both(cfg, tmp_path)
        _same_values(distributed, inprocess)
        assert meta(inprocess).get("step_sizes") == meta(distributed).get("step_sizes")
        assert (inprocess / "events.jsonl").read_bytes() == (distributed / "events.jsonl").read_bytes()
    assert "localised" in (inprocess / "events.jsonl").read_text()
    assert meta(inprocess)["steps"] > 16  # the event's grid: more points than 0.8 / 0.05


def test_the_shipped_configs_it_accepts_record_what_they_record_in_processes(tmp_path):
    build_scene_fmus(REPO / "hycosim" / "scenario" / "build" / "fmus")
    for name in ("grasp", "grasp-fmu", "grasp-policy"):
        doc = json.loads((REPO / "hycosim" / "scenario" / "configs" / f"{name}.json").read_text())
        doc["coSimulation"]["stopTime"] = 2.5  # past the grasp: a mode switch in both
        cfg = REPO / "hycosim" / "scenario" / "configs" / f".{name}-short-{tmp_path.name}.json"  # FMU paths are relative to it
        cfg.write_text(json.dumps(doc))
        try:
            distributed, inprocess = _run_both(cfg, tmp_path)
        finally:
            cfg.unlink()
        _same_values(distributed, inprocess)
        assert (inprocess / "events.jsonl").read_text().count('"to": "grasp"') == 1


def test_a_replayed_node_and_an_ssp_package_record_the_same_values_in_process(tmp_path):
    doc = json.loads((REPO / "hycosim" / "scenario" / "configs" / "grasp.json").read_text())
    doc["coSimulation"]["stopTime"] = 1.0
    (cfg := tmp_path / "grasp.json").write_text(json.dumps(doc))
    recorded = run_project(cfg, tmp_path / "recorded")
    for n in doc["nodeLists"]:
        if n["nodeName"] == "robot":
            n["replay"] = str(recorded)
    (replayed := tmp_path / "replayed.json").write_text(json.dumps(doc))
    distributed, inprocess = _run_both(replayed, tmp_path)
    _same_values(distributed, inprocess)
    _same_values(recorded, inprocess)
    config, package = _small_fmus.write_package(tmp_path / "small", 300)
    distributed, inprocess = _run_both(package, tmp_path)
    _same_values(distributed, inprocess)
    rows = read_rows(inprocess)
    assert len(rows) == 301 and float(rows[1]["ft.u"]) == 2 * float(rows[1]["dahlquist.x"]) + 1


def test_fmu_ports_of_three_types_record_the_same_values_in_process(tmp_path):
    # In process an FMU steps on the master's lists, its outputs read from its buffers as they are.
    fmus = _small_fmus.build(tmp_path / "fmus")
    nodes = [{"nodeName": "src", "UID": 1, "model": "ramp", "output": ["y", "v"]},
             {"nodeName": "typed", "UID": 2, "fmu": str(fmus["Types"]), "parameters": {"offset": 3, "gain": 2.0},
              "input": [{"name": "ru", "type": "Real"}, {"name": "iu", "type": "Integer"},
                        {"name": "bu", "type": "Boolean", "start": True}],
              "output": [{"name": "ry", "type": "Real"}, {"name": "iy", "type": "Integer"},
                         {"name": "by", "type": "Boolean"}]}]
    cfg = write_project(tmp_path / "types.json", nodes, [{"from": "src.y", "to": "typed.ru"}],
                        cosim={"stepSize": 0.1, "stopTime": 1.0})
    distributed, inprocess = _run_both(cfg, tmp_path)
    assert (distributed / "values.csv").read_bytes() == (inprocess / "values.csv").read_bytes()
    rows = read_rows(inprocess)
    assert {(r["typed.iy"], r["typed.bu"], r["typed.by"]) for r in rows[1:]} == {("3", "1", "0")}  # by = not bu
    assert [float(r["typed.ry"]) for r in rows[1:]] == [2 * float(r["typed.ru"]) for r in rows[:-1]]


def test_a_node_one_process_cannot_host_is_named_and_nothing_is_run(tmp_path):
    res = hycosim("run", str(REPO / "hycosim" / "configs" / "default.json"), "--in-process", "--runs-dir",
                  str(tmp_path / "runs"))
    assert res.returncode == 2 and "node 'sensor': an asynchronous source" in res.stderr, res.stderr
    assert not (tmp_path / "runs").exists()
    doc = json.loads((REPO / "hycosim" / "scenario" / "configs" / "grasp.json").read_text())
    doc["coSimulation"]["transport"] = "inprocess"
    (cfg := tmp_path / "grasp.json").write_text(json.dumps(doc))
    res = hycosim("run", str(cfg), "--listen", "tcp/127.0.0.1:7447", "--runs-dir", str(tmp_path / "runs"))
    assert res.returncode == 2 and "--listen is for a run in processes" in res.stderr, res.stderr
    build_scene_fmus(REPO / "hycosim" / "scenario" / "build" / "fmus")  # where the shipped config names them
    res = hycosim("validate", str(REPO / "hycosim" / "scenario" / "configs" / "grasp-paper.json"))
    assert res.returncode == 0 and "in one process (--in-process): no, node 'camera'" in res.stdout, res.stdout


def test_a_node_that_fails_in_process_ends_the_run_with_its_words_and_the_rows_before_stay(tmp_path):
    nodes = [{"nodeName": "src", "UID": 1, "model": "ramp", "output": ["y", "v"]},
             {"nodeName": "bad", "UID": 2, "model": "tests.nodes:FailsAt", "input": ["u"], "output": ["y"]}]
    cfg = write_project(tmp_path / "bad.json", nodes, [{"from": "src.y", "to": "bad.u"}],
                        cosim={"stepSize": 0.1, "stopTime": 2.0, "transport": "inprocess"})
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress")
    run_dir = next((tmp_path / "runs").iterdir())
    assert res.returncode == 3 and "node 'bad': its model failed at step 5" in res.stderr, res.stderr
    assert "ZeroDivisionError: the model divided by zero" in res.stderr
    assert meta(run_dir)["status"] == "failed" and "node 'bad'" in meta(run_dir)["reason"]
    assert [float(r["bad.y"]) for r in read_rows(run_dir)] == pytest.approx([k / 10 for k in range(6)])


def test_a_model_that_ends_the_run_inside_a_step_ends_it_at_the_same_point_in_process(tmp_path):
    # Each macro step a call in process (no frame); the END still comes as a frame, and the run
    # ends where the distributed run ends: the points before, then the point where the model ended.
    nodes = [{"nodeName": "src", "UID": 1, "model": "ramp", "output": ["y", "v"]},
             {"nodeName": "end", "UID": 2, "model": "tests.nodes:EndsAt", "input": ["u"], "output": ["y"]},
             {"nodeName": "gain", "UID": 3, "model": "gain", "parameters": {"k": 2.0},
              "input": ["u"], "output": ["y"]}]
    cfg = write_project(tmp_path / "ends.json", nodes, [{"from": "src.y", "to": "end.u"},
                                                        {"from": "end.y", "to": "gain.u"}],
                        cosim={"stepSize": 0.1, "stopTime": 2.0})
    distributed, inprocess = _run_both(cfg, tmp_path)
    _same_values(distributed, inprocess)
    assert meta(inprocess)["ended_by"] == meta(distributed)["ended_by"]
    assert meta(inprocess)["ended_by"]["t"] == 0.45 and meta(inprocess)["status"] == "completed"
    assert [float(r["t"]) for r in read_rows(inprocess)][-2:] == [0.4, 0.45]
    assert meta(inprocess)["releases"] == "calls (in process)"
    assert meta(distributed)["releases"] == "frames (nodes in processes of their own)"


# Anything released on the bus (well-formed or not) reaches a hosted node only through its
# checks: nothing raises into the master's call, and what the node answers is a frame of its own.
@settings(max_examples=200)
@given(st.lists(payloads, min_size=1, max_size=4))
def test_a_hosted_node_takes_anything_released_without_raising_into_the_master(gain_project, released):
    from hycosim.node.loader import load_node
    from hycosim.node.in_process import HostedNode

    bus = LocalBus(gain_project.project.projectName)
    runtime = HostedNode(gain_project, "g", load_node(gain_project.project.node("g"), REPO,
                                                       gain_project.project.coSimulation), "inprocess")
    runtime.host(bus)
    try:
        bus.release.put(frames.encode(frames.START, "r", 0.0, 0.1, 0.0, None, {"checkpoint": False}))
        for payload in released:
            bus.release.put(payload)
    finally:
        runtime.close()
    answered = []
    while (msg := bus.inbox.recv(0.0)) is not None:
        answered.append(frames.decode(msg[1]))
    assert [f.kind for f in answered[:3]] == [frames.LIVE, frames.HELLO, frames.OUTPUTS]
    for f in answered[3:]:
        assert f.kind in (frames.OUTPUTS, frames.BATCH, frames.END, frames.LIVE), f
        if f.kind == frames.OUTPUTS:  # a release it took: its step's outputs, labelled as the master expects
            assert type(f.values[0]) is float and f.uid == 1


@pytest.fixture(scope="module")
def gain_project(tmp_path_factory):
    nodes = [{"nodeName": "g", "UID": 1, "model": "gain", "input": ["u"], "output": ["y"]}]
    return load_project(write_project(tmp_path_factory.mktemp("hosted") / "g.json", nodes,
                                      cosim={"stepSize": 0.1, "stopTime": 1.0}))
