"""Runs that survive a crash: checkpoints, node restarts, server resume (real processes, real kills)."""

from __future__ import annotations

import hashlib
import json
import re
import shutil
from pathlib import Path

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core import frames
from server import checkpoints
from server.interpolation import MAX_DEGREE, InputTrack
from tests.helpers import REPO, hycosim, meta, run_killing, run_project, write_project
from tests.wire_strategies import deep_json

from clients.node import NodeContext


def _project(tmp_path: Path, every: float | None = 0.5, clock: bool = False) -> Path:
    """Four nodes, the MuJoCo rod among them; one gain takes a little time per step so that a
    kill lands mid-run."""
    nodes = [
        {"nodeName": "rod", "UID": 1, "model": "clients.rod.node:RodNode", "parameters": {"initial_angle_deg": 35},
         "input": [], "output": ["angle", "omega"]},
        {"nodeName": "pend", "UID": 2, "model": "pendulum", "parameters": {"theta0": 0.5}, "input": ["theta_in"],
         "output": ["theta", "omega"]},
        {"nodeName": "g1", "UID": 3, "model": "gain", "parameters": {"k": 2.0}, "input": ["u"], "output": ["y"]},
        {"nodeName": "g2", "UID": 4, "model": "tests.nodes:Clock" if clock else "gain",
         "parameters": {} if clock else {"k": 0.5, "work_s": 0.003}, "input": [] if clock else ["u"],
         "output": ["y"]},
    ]
    links = [{"from": "rod.angle", "to": "g1.u"}, {"from": "rod.omega", "to": "pend.theta_in"}]
    if not clock:
        links.append({"from": "g1.y", "to": "g2.u"})
    cosim = {"stepSize": 0.01, "stopTime": 8.0, "attachTimeout": 20.0}
    if every is not None:
        cosim["checkpointEvery"] = every
    return write_project(tmp_path / "p.json", nodes, links, cosim=cosim, name="rec")


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> bytes:
    tmp = tmp_path_factory.mktemp("reference")
    run = run_project(_project(tmp), tmp / "runs")
    return (run / "values.csv").read_bytes()


def test_a_run_whose_nodes_are_killed_records_what_a_run_never_killed_does(tmp_path, reference):
    cfg = _project(tmp_path)
    runs = tmp_path / "runs"
    code, err = run_killing(cfg, runs, [("node rod", 150), ("node g2", 450)], "--restarts", "2")
    assert code == 0, err
    run = next(runs.iterdir())
    assert (run / "values.csv").read_bytes() == reference
    m = meta(run)
    restored = [(r["node"], r["cause"]) for r in m["recoveries"]]
    assert restored == [("rod", "restarted"), ("g2", "restarted")]
    for r in m["recoveries"]:
        assert r["restored"] <= r["step"] and r["restored"] % 50 == 0  # back to a checkpoint at most 0.5 s old
    assert len(checkpoints.steps(run)) == checkpoints.KEEP
    assert "started again (1 of 2)" in (run / "node-rod.stderr.txt").read_text()


def test_a_resumed_server_goes_on_from_its_last_good_checkpoint_and_records_the_same(tmp_path, reference):
    cfg = _project(tmp_path)
    runs = tmp_path / "runs"
    code, err = run_killing(cfg, runs, [("server", 400)])
    assert code == 3 and "died of SIGKILL" in err and "--resume" in err
    run = next(runs.iterdir())
    newest = checkpoints.steps(run)[-1]
    state = run / "checkpoints" / str(newest) / "rod.state"
    state.write_bytes(state.read_bytes()[:-5])  # a truncated checkpoint: the one before it is used
    res = hycosim("run", str(cfg), "--resume", str(run), "--no-progress", timeout=120)
    assert res.returncode == 0, res.stderr
    assert (run / "values.csv").read_bytes() == reference
    m = meta(run)
    resumed = m["recoveries"][-1]
    assert resumed["node"] == "server" and resumed["cause"] == "resumed" and resumed["restored"] < newest
    assert any("rod.state is truncated" in why for why in m["checkpoints_passed_over"])
    assert m["status"] == "completed" and m["steps"] == 801


def test_resume_refuses_another_project_file_naming_the_difference(tmp_path):
    cfg = _project(tmp_path)
    run = run_project(cfg, tmp_path / "runs")
    doc = json.loads(cfg.read_text())
    doc["coSimulation"]["stopTime"] = 9.0
    other = tmp_path / "other.json"
    other.write_text(json.dumps(doc))
    res = hycosim("server", str(other), "--resume", str(run))
    assert res.returncode == 2
    assert "another project file" in res.stderr and "coSimulation.stopTime: 8.0 → 9.0" in res.stderr


def test_a_node_that_cannot_serialise_is_named_by_validate_and_by_the_run_it_ends(tmp_path):
    cfg = _project(tmp_path, clock=True)
    res = hycosim("validate", str(cfg))
    assert res.returncode == 0 and "node 'g2' cannot take part in checkpoints" in res.stderr
    runs = tmp_path / "runs"
    code, err = run_killing(cfg, runs, [("node rod", 100)])
    assert code == 3
    assert "node 'rod' was" in err and "g2 cannot serialise their state" in err
    assert meta(next(runs.iterdir()))["checkpoints"] == "off: g2 cannot serialise their state"


def test_checkpoints_are_written_whole_kept_two_deep_and_checked_when_read(tmp_path):
    server = {"step": 0, "t": 0.0, "origin": 0.0, "j": 0, "mode": "free", "disarmed": [], "outputs": {},
              "inputs": {}, "histories": {}, "records": dict.fromkeys(checkpoints.RECORD_FILES, 0), "localised": {}, "h": 0.01}
    for step in (10, 20, 30):
        checkpoints.write(tmp_path, step, {**server, "step": step}, {"a": bytes([step]) * 100}, "hash")
    assert checkpoints.steps(tmp_path) == [20, 30]
    assert not any(p.name.startswith(".") for p in (tmp_path / "checkpoints").iterdir())
    cp, passed = checkpoints.latest(tmp_path, "hash")
    assert cp.step == 30 and cp.states == {"a": bytes([30]) * 100} and passed == []
    (tmp_path / "checkpoints" / "30" / "a.state").write_bytes(bytes([31]) * 100)  # same size, other bytes
    cp, passed = checkpoints.latest(tmp_path, "hash")
    assert cp.step == 20 and "a.state is damaged" in passed[0]
    cp, passed = checkpoints.latest(tmp_path, "other")
    assert cp is None and all("another project file" in why for why in passed)


def _continue_identically(make, inputs: dict, steps: int = 25) -> int:
    """Step a node, move its state to a fresh one, and step both on: return the state's size."""
    a = make()
    for k in range(steps):
        a.step(k * 0.01, 0.01, inputs)
    data = a.serialize_state()
    b = make()
    b.deserialize_state(data)
    assert a.outputs() == b.outputs()
    for k in range(steps, 2 * steps):
        a.step(k * 0.01, 0.01, inputs)
        b.step(k * 0.01, 0.01, inputs)
        ours, theirs = a.outputs(), b.outputs()
        ours.pop("infer_ms", None), theirs.pop("infer_ms", None)  # a wall-clock measurement
        assert ours == theirs, k
    return len(data)


@pytest.mark.parametrize("model", ["clients.rod.node:RodNode", "clients.robot.node:RobotNode",
                                   "clients.robot.controller:ReferenceController", "clients.policy.node:PolicyNode"])
def test_a_scenario_node_goes_on_in_another_process_from_its_state(model):
    import importlib

    module, cls = model.split(":")
    node_cls = getattr(importlib.import_module(module), cls)

    def make():
        node = node_cls()
        node.setup(NodeContext("n", 1, [], [], {"observer_gain": 4.0} if cls == "RodNode" else {}, 0.01, 0.0))
        return node

    inputs = {"meas_angle": 0.5, "meas_valid": 1.0, "meas_t": 0.05, "q_cmd1": 0.3, "rod_angle": 0.4,
              "rod_omega": -0.2, "grasped": 0.0, "gap": 0.05, "dist": 0.2, **{f"q{i + 1}": 0.1 for i in range(6)},
              "grasp_x": 0.6, "grasp_y": 0.2, "grasp_z": 0.7, "tcp_x": 0.5, "tcp_y": 0.0, "tcp_z": 0.8}
    assert _continue_identically(make, inputs) < frames.STATE_CHUNK


def test_the_scene_fmus_serialise_their_whole_state(tmp_path):
    from clients.scene_fmus import ensure_scene_fmus
    from core.config import load_project
    from clients.loader import load_node

    ensure_scene_fmus(REPO / "build" / "fmus")
    loaded = load_project(REPO / "configs" / "grasp-paper.json")
    for name in ("rod", "robot"):
        spec = loaded.project.node(name)
        made = []

        def make():
            node = load_node(spec, REPO / "configs")
            node.setup(NodeContext(name, spec.UID, list(spec.input), list(spec.output), dict(spec.parameters), 0.01,
                                   0.0, project_dir=REPO / "configs"))
            made.append(node)
            return node

        try:
            _continue_identically(make, {p.name: p.start_value() for p in spec.input})
        finally:
            for node in made:
                node.teardown()


# What a hand, a full disk or a crash may leave in a checkpoint folder or a run directory.
_json_values = st.recursive(st.none() | st.booleans() | st.integers(-3, 1 << 40) | st.floats(allow_nan=False)
                            | st.text(max_size=12),
                            lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=14), inner,
                                                                                        max_size=4), max_leaves=12)
_file_names = (st.sampled_from(["server.msgpack", "a.state", "../a.state", ".", "", "manifest.json", "\x00", "/etc/hosts"])
               | st.text(max_size=8))


@st.composite
def _checkpoint_folders(draw):
    """A plausible manifest (sizes and hashes right or not) over files of plausible or random bytes."""
    server = draw(st.fixed_dictionaries({
        "step": st.integers(-1, 5) | st.integers(-(2 ** 63), 2 ** 64 - 1), "t": st.floats() | st.integers(0, 2), "origin": st.floats(),
        "j": st.integers(0, 3), "mode": st.text(max_size=5), "disarmed": st.lists(st.text(max_size=3), max_size=2),
        "outputs": st.dictionaries(st.text(max_size=3), _json_values, max_size=2),
        "inputs": st.dictionaries(st.text(max_size=3), _json_values, max_size=2),
        "histories": st.dictionaries(st.text(max_size=3), _json_values, max_size=2),
        "records": st.dictionaries(st.sampled_from(sorted(checkpoints.RECORD_FILES)) | st.text(max_size=4),
                                   st.integers(-2, 100) | _json_values, max_size=4),
        "localised": _json_values, "h": st.floats() | st.integers(0, 2)}, optional={
        # Iterative coupling's interpolated inputs: the points before the checkpoint's.
        "track": st.none() | _json_values | st.fixed_dictionaries({"mode": st.none() | st.text(max_size=3), "points": st.lists(
            st.lists(st.floats() | st.dictionaries(st.text(max_size=3), _json_values, max_size=2), max_size=3),
            max_size=5)})}) | _json_values)
    files = {"server.msgpack": draw(st.just(msgpack.packb(server, use_bin_type=True)) | st.binary(max_size=40))}
    files.update(draw(st.dictionaries(_file_names, st.binary(max_size=20), max_size=3)))
    honest = draw(st.booleans())
    manifest = {"step": draw(_json_values), "config_sha256": draw(st.sampled_from(["h", "other"])),
                "nodes": draw(st.lists(st.sampled_from(["a", "b"]) | _json_values, max_size=3)),
                "files": {name: {"size": len(data) if honest else draw(_json_values),
                                 "sha256": hashlib.sha256(data).hexdigest() if honest else draw(_json_values)}
                          for name, data in files.items()}}
    text = draw(st.just(json.dumps(manifest)) | st.text(max_size=30) | _json_values.map(json.dumps) | deep_json)
    return files, text


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(_checkpoint_folders())
def test_a_checkpoint_folder_is_read_whole_or_refused_with_its_name(tmp_path, folder):
    files, manifest = folder
    path = tmp_path / "checkpoints" / "7"
    shutil.rmtree(tmp_path / "checkpoints", ignore_errors=True)
    path.mkdir(parents=True)
    for name, data in files.items():
        if re.fullmatch(r"[A-Za-z0-9_.\-]+", name) and name not in (".", ".."):
            (path / name).write_bytes(data)
    (path / checkpoints.MANIFEST).write_text(manifest)
    try:
        cp = checkpoints.read(path, "h")
    except checkpoints.CheckpointError as exc:
        assert str(path) in str(exc)
        return
    assert set(cp.server["records"]) == checkpoints.RECORD_FILES and 0 <= cp.step
    assert all(type(data) is bytes for data in cp.states.values())
    if cp.server.get("track") is not None:  # points a run can step on again
        InputTrack(MAX_DEGREE, []).restore(cp.server["track"])


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture], max_examples=40)
@given(st.text(max_size=40) | _json_values.map(json.dumps) | deep_json)
def test_a_resume_reads_any_meta_json_without_a_traceback(tmp_path, meta_text):
    from core.config import load_project
    from server.main import _resume_plan

    cfg = _project(tmp_path)
    (tmp_path / "meta.json").write_text(meta_text)
    with pytest.raises(ValueError) as exc:  # no checkpoint here: every path ends in a refusal
        _resume_plan(load_project(cfg), tmp_path)
    assert str(tmp_path) in str(exc.value) or "another project file" in str(exc.value)
