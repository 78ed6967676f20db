"""Runs that survive a crash: checkpoints, node restarts, server resume (real processes, real kills)."""

from __future__ import annotations

import hashlib
import json
import math
import re
import shutil
from pathlib import Path

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hycosim.core import frames
from hycosim.master import checkpoints
from hycosim.master.interpolation import MAX_DEGREE, InputTrack
from tests.helpers import (REPO, hycosim, kill_process, meta, reap, recorded_rows, run_killing, run_project, spawn, wait_for,
                           write_project)
from tests.wire_strategies import deep_json

from hycosim.node.interface import NodeContext


def _project(tmp_path: Path, every: float | None = 0.5, clock: bool = False) -> Path:
    """Four nodes, the MuJoCo rod among them; one gain takes a little time per step so that a
    kill lands mid-run (g2, or g1 where g2 is a clock that cannot serialise)."""
    nodes = [
        {"nodeName": "rod", "UID": 1, "model": "hycosim.scenario.rod.node:RodNode", "parameters": {"initial_angle_deg": 35},
         "input": [], "output": ["angle", "omega"]},
        {"nodeName": "pend", "UID": 2, "model": "pendulum", "parameters": {"theta0": 0.5}, "input": ["theta_in"],
         "output": ["theta", "omega"]},
        {"nodeName": "g1", "UID": 3, "model": "gain", "parameters": {"k": 2.0, "work_s": 0.003} if clock else {"k": 2.0},
         "input": ["u"], "output": ["y"]},
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


def test_a_node_killed_before_the_run_starts_is_started_again_without_checkpoints(tmp_path):
    """Issue 59, part 6: the rod's process is killed once it has attached, while a slow node
    still loads (the run cannot have started). Nothing of it is lost: its new process attaches
    as the first did, and the run records what a run never killed does."""
    cfg = _project(tmp_path, every=None)
    doc = json.loads(cfg.read_text())
    doc["coSimulation"]["stopTime"] = 2.0
    doc["nodeLists"].append({"nodeName": "late", "UID": 5, "model": "tests.nodes:SlowStart",
                             "parameters": {"setup_s": 6.0}, "input": [], "output": ["y"]})
    doc["nodeNum"] = len(doc["nodeLists"])
    cfg.write_text(json.dumps(doc))
    reference = run_project(cfg, tmp_path / "reference")
    runs = tmp_path / "runs"
    proc = spawn("run", str(cfg), "--runs-dir", str(runs), "--no-progress", "--restarts", "2")
    try:
        log = lambda: next(runs.iterdir()) / "node-rod.log.jsonl"  # noqa: E731
        wait_for(lambda: runs.exists() and any(runs.iterdir()) and log().exists()
                 and "server seen" in log().read_text(), 60, "the rod attached")
        assert recorded_rows(runs) == 0  # the run has not started
        kill_process(f"hycosim node rod {cfg}")
        _, err = proc.communicate(timeout=120)
    finally:
        reap(proc)
    assert proc.returncode == 0, err
    run = next(runs.iterdir())
    assert (run / "values.csv").read_bytes() == (reference / "values.csv").read_bytes()
    said = (run / "node-rod.stderr.txt").read_text()
    assert "started again (1 of 2): its process died of SIGKILL before the run started" in said
    assert meta(run)["status"] == "completed"


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
    assert sum("rod.state is truncated" in why for why in m["checkpoints_passed_over"]) == 1  # said once
    assert m["status"] == "completed" and m["steps"] == 801


def test_a_resume_passes_over_a_checkpoint_edited_to_hold_what_the_project_cannot(tmp_path, reference):
    """The newest checkpoint edited by hand, its manifest re-hashed to match: g1's output now a
    string. The resume names it, goes on from the one before and records what a run never
    stopped does. Before, the string was routed to g2, which refused every release, and the
    resumed run timed out."""
    cfg = _project(tmp_path)
    run = run_project(cfg, tmp_path / "runs")
    older, newest = checkpoints.steps(run)
    folder = run / "checkpoints" / str(newest)
    state = msgpack.unpackb((folder / checkpoints.SERVER_FILE).read_bytes(), raw=False)
    state["outputs"]["g1"] = ["2.0"]
    data = msgpack.packb(state, use_bin_type=True)
    (folder / checkpoints.SERVER_FILE).write_bytes(data)
    manifest = json.loads((folder / checkpoints.MANIFEST).read_text())
    manifest["files"][checkpoints.SERVER_FILE] = {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}
    (folder / checkpoints.MANIFEST).write_text(json.dumps(manifest))
    res = hycosim("run", str(cfg), "--resume", str(run), "--no-progress", timeout=120)
    assert res.returncode == 0, res.stderr
    assert (run / "values.csv").read_bytes() == reference
    m = meta(run)
    assert m["recoveries"][-1]["restored"] == older
    assert m["checkpoints_passed_over"] == [
        f"{folder} does not fit the project: its outputs of g1: y holds str '2.0', not a Real"]


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
    for stray in ("²", "٣", "1e3", ".40.partial"):  # "²".isdigit() holds, and int() refuses it
        (tmp_path / "checkpoints" / stray).mkdir()
    assert checkpoints.steps(tmp_path) == [20, 30]
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


@pytest.mark.parametrize("model", ["hycosim.scenario.rod.node:RodNode", "hycosim.scenario.robot.node:RobotNode",
                                   "hycosim.scenario.robot.controller:ReferenceController", "hycosim.scenario.policy.node:PolicyNode"])
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
    from hycosim.scenario.scene_fmus import ensure_scene_fmus
    from hycosim.core.config import load_project
    from hycosim.node.loader import load_node

    ensure_scene_fmus(REPO / "hycosim" / "scenario" / "build" / "fmus")  # where the shipped config names them (make fmus)
    loaded = load_project(REPO / "hycosim" / "scenario" / "configs" / "grasp-paper.json")
    for name in ("rod", "robot"):
        spec = loaded.project.node(name)
        made = []

        def make():
            node = load_node(spec, REPO / "hycosim" / "scenario" / "configs")
            node.setup(NodeContext(name, spec.UID, list(spec.input), list(spec.output), dict(spec.parameters), 0.01,
                                   0.0, project_dir=REPO / "hycosim" / "scenario" / "configs"))
            made.append(node)
            return node

        try:
            _continue_identically(make, {p.name: p.start_value() for p in spec.input})
        finally:
            for node in made:
                node.teardown()


# What a hand, a full disk or a crash may leave in a checkpoint folder or a run directory.
def _json_containers(inner: st.SearchStrategy) -> st.SearchStrategy:
    # A function, not a lambda over two lines: hypothesis reads a lambda's source to see that
    # it uses its argument, and over two lines it does not find it (a deprecation warning).
    return st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=14), inner, max_size=4)


_json_values = st.recursive(st.none() | st.booleans() | st.integers(-3, 1 << 40) | st.floats(allow_nan=False)
                            | st.text(max_size=12), _json_containers, max_leaves=12)
_file_names = (st.sampled_from(["server.msgpack", "a.state", "../a.state", ".", "", "manifest.json", "\x00", "/etc/hosts"])
               | st.text(max_size=8))


@st.composite
def _checkpoint_folders(draw):
    """A plausible manifest (sizes and hashes right or not) over files of plausible or random bytes."""
    server = draw(st.fixed_dictionaries({
        "step": st.integers(-1, 5) | st.integers(-(2 ** 63), 2 ** 64 - 1), "t": st.floats() | st.integers(0, 2), "origin": st.floats(),
        "j": st.integers(0, 3), "mode": st.text(max_size=5), "disarmed": st.lists(st.text(max_size=3) | _json_values, max_size=2),
        "outputs": st.dictionaries(st.text(max_size=3), _json_values, max_size=2),
        "inputs": st.dictionaries(st.text(max_size=3), _json_values, max_size=2),
        "histories": st.dictionaries(st.text(max_size=3), _json_values | st.fixed_dictionaries({
            "samples": st.lists(st.lists(st.floats() | st.lists(_json_values, max_size=2) | _json_values, max_size=3),
                                max_size=3), "received": st.integers(-1, 3) | _json_values}), max_size=2),
        "records": st.dictionaries(st.sampled_from(sorted(checkpoints.RECORD_FILES)) | st.text(max_size=4),
                                   st.integers(-2, 100) | _json_values, max_size=4),
        "localised": _json_values | st.dictionaries(st.text(max_size=3), st.binary(max_size=2) | st.floats()),
        "h": st.floats() | st.integers(0, 2)}, optional={
        # The master algorithm's: iterative coupling's interpolated inputs (the points before
        # the checkpoint's), a controlled step's next length, or anything of a user's algorithm.
        "algorithm": _json_values | st.fixed_dictionaries({}, optional={
            "track": st.none() | _json_values | st.fixed_dictionaries({"mode": st.none() | st.text(max_size=3),
                                                                       "points": st.lists(st.lists(
                st.floats() | st.dictionaries(st.text(max_size=3), _json_values, max_size=2), max_size=3),
                max_size=5)}),
            "h": st.floats() | _json_values})}) | _json_values)
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
    state = cp.server  # what the relay takes back: each of the types it was written with
    assert set(state["records"]) == checkpoints.RECORD_FILES and 0 <= cp.step == state["step"]
    assert all(type(data) is bytes for data in cp.states.values())
    assert all(type(state[k]) is float and math.isfinite(state[k]) for k in ("t", "origin", "h"))
    assert state["origin"] <= state["t"] and 0 <= state["j"] <= state["step"] and state["h"] > 0
    assert all(type(name) is str for name in state["disarmed"])  # the relay makes a set of them
    json.dumps(state["localised"], allow_nan=False)  # recorded with the switch a located event finds
    for history in state["histories"].values():
        times = [t for t, values in history["samples"]]
        assert all(math.isfinite(t) for t in times) and times == sorted(set(times))
        assert all(type(values) is list for _, values in history["samples"])
    json.dumps(state["algorithm"], allow_nan=False)  # the master algorithm's own (MasterAlgorithm.restore)
    if state["algorithm"].get("track") is not None:  # points a run can step on again
        InputTrack(MAX_DEGREE, []).restore(state["algorithm"]["track"])


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture], max_examples=40)
@given(st.text(max_size=40) | _json_values.map(json.dumps) | deep_json)
def test_a_resume_reads_any_meta_json_without_a_traceback(tmp_path, meta_text):
    from hycosim.core.config import load_project
    from hycosim.master.main import _resume_plan

    cfg = _project(tmp_path)
    (tmp_path / "meta.json").write_text(meta_text)
    with pytest.raises(ValueError) as exc:  # no checkpoint here: every path ends in a refusal
        _resume_plan(load_project(cfg), tmp_path)
    assert str(tmp_path) in str(exc.value) or "another project file" in str(exc.value)


# A project whose checkpoints hold every kind of part: an asynchronous source's samples, ports
# of four types, an event to be in or disarmed. The strategy below draws a checkpoint as the
# relay writes one for it, with at most one thing wrong.
_FIT_NODES = [
    {"nodeName": "src", "UID": 1, "model": "ramp_source", "async": True, "rate": 10,
     "output": ["a", {"name": "n", "type": "Integer"}]},
    {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u", {"name": "on", "type": "Boolean"}],
     "output": ["y", {"name": "label", "type": "String"}]},
]
_FIT_EVENTS = [{"name": "hold", "when": "src.a >= 1", "drives": "g", "until": "src.a < 0.5"}]
_finite = st.floats(-1e6, 1e6, allow_nan=False)
_VALUES = {"Real": _finite | st.integers(-5, 5), "Integer": st.integers(-(2 ** 40), 2 ** 40),
           "Boolean": st.booleans(), "String": st.text(max_size=4)}
_NOT = {"Real": st.text(max_size=2) | st.booleans() | st.none(), "Integer": _finite | st.booleans() | st.text(max_size=2),
        "Boolean": st.integers(0, 1) | _finite, "String": st.binary(max_size=2) | _finite | st.none()}
_TYPES = {"src": ["Real", "Integer"], "g": ["Real", "String"]}
_IN_TYPES = {"src": [], "g": ["Real", "Boolean"]}

# What may be wrong, and whether reading alone (shape) or only the project (fit) tells it.
_STATE_WRONGS = {
    "step": "shape", "t": "shape", "origin": "shape", "j": "shape", "h": "shape", "disarmed": "shape",
    "records": "shape", "localised": "shape", "history": "shape", "track": "shape", "key": "shape",
    "time": "fit", "mode": "fit", "event": "fit", "ports": "fit", "type": "fit", "source": "fit", "sample": "fit",
}
_FOLDER_WRONGS = ["manifest", "size", "sha256", "file name", "config", "state missing", "truncated", "not msgpack"]


@st.composite
def _server_states(draw, wrong: str | None):
    """A server state as the relay writes one for the project above (wrong in ``wrong``, if given)."""
    step = draw(st.integers(0, 200))
    j = draw(st.integers(0, step))
    origin = draw(st.floats(0, 2))
    t = draw(st.floats(origin, 2))
    values = {n: [draw(_VALUES[tp]) for tp in tps] for n, tps in _TYPES.items()}
    times = sorted(set(draw(st.lists(st.floats(-1, 2), max_size=4))))
    state = {
        "step": step, "t": t, "origin": origin, "j": j, "mode": draw(st.sampled_from(["free", "hold"])),
        "disarmed": draw(st.lists(st.just("hold"), max_size=1)), "outputs": values,
        "inputs": {n: [draw(_VALUES[tp]) for tp in tps] for n, tps in _IN_TYPES.items()},
        "histories": {"src": {"samples": [[s, [draw(_VALUES[tp]) for tp in _TYPES["src"]]] for s in times],
                              "received": draw(st.integers(len(times), 99))}},
        "records": {name: draw(st.integers(0, 1 << 40)) for name in sorted(checkpoints.RECORD_FILES)},
        "localised": draw(st.just({}) | st.fixed_dictionaries({"bracket": st.lists(_finite, max_size=2)})),
        "h": draw(st.floats(1e-6, 1)), "algorithm": {},
    }
    if wrong == "step":
        state["step"] = draw(st.sampled_from([-1, 1 << 62, 1.5, True, "3", None]))
    elif wrong in ("t", "origin", "h"):
        state[wrong] = draw(st.sampled_from([math.nan, math.inf, -math.inf, "0", True, None]
                                            + ([0.0, -0.5] if wrong == "h" else [])))
    elif wrong == "j":
        state["j"] = draw(st.sampled_from([-1, step + 1, 0.0, False]))
    elif wrong == "disarmed":
        state["disarmed"] = draw(st.sampled_from([[["hold"]], [1], "hold", {"hold": 1}]))
    elif wrong == "records":
        which = draw(st.sampled_from(sorted(checkpoints.RECORD_FILES)))
        change = draw(st.sampled_from(["gone", "negative", "float", "extra"]))
        if change == "gone":
            del state["records"][which]
        elif change == "extra":
            state["records"]["other.csv"] = 0
        else:
            state["records"][which] = -1 if change == "negative" else 1.0
    elif wrong == "localised":
        state["localised"] = draw(st.sampled_from([{"x": b"\x00"}, {"x": math.nan}, [1], "x", {"x": [math.inf]}]))
    elif wrong == "history":
        change = draw(st.sampled_from(["unsorted", "nan", "shape", "received"]))
        samples = state["histories"]["src"]["samples"]
        if change == "unsorted":
            samples[:] = [[1.0, [0.5, 1]], [draw(st.floats(-1, 1)), [0.5, 1]]]
        elif change == "nan":
            samples[:] = [[math.nan, [0.5, 1]]]
        elif change == "shape":
            samples[:] = [draw(st.sampled_from([[0.5], [0.5, 1.0], ["0.5", [1.0, 1]], [0.5, [1.0, 1], 3]]))]
        else:
            state["histories"]["src"]["received"] = draw(st.sampled_from([-1, 1.0, None]))
    elif wrong == "track":
        state["algorithm"] = {"track": draw(st.sampled_from([{"points": [[math.nan, {}]]}, {"points": "x"}, [1],
                                                             {"mode": 3, "points": []}]))}
    elif wrong == "key":
        if draw(st.booleans()):
            del state[draw(st.sampled_from(sorted(k for k in state if k != "algorithm")))]
        else:
            state["extra"] = 1
    elif wrong == "time":
        state["t"] = state["origin"] = draw(st.sampled_from([-0.5, 2.5, 1e9]))
        state["j"] = 0
    elif wrong == "mode":
        state["mode"] = draw(st.sampled_from(["nope", "", "Free"]))
    elif wrong == "event":
        state["disarmed"] = ["nope"]
    elif wrong == "ports":
        which = draw(st.sampled_from(["outputs", "inputs"]))
        change = draw(st.sampled_from(["node gone", "node added", "longer", "shorter"]))
        ports = state[which]
        if change == "node gone":
            del ports[draw(st.sampled_from(["src", "g"]))]
        elif change == "node added":
            ports["other"] = []
        elif change == "longer":
            ports["g"].append(0.0)
        else:
            ports["g"].pop()
    elif wrong == "type":
        which = draw(st.sampled_from(["outputs", "inputs"]))
        node = "src" if which == "outputs" and draw(st.booleans()) else "g"
        types = (_TYPES if which == "outputs" else _IN_TYPES)[node]
        i = draw(st.integers(0, len(types) - 1))
        state[which][node][i] = draw(_NOT[types[i]])
    elif wrong == "source":
        state["histories"]["g"] = {"samples": [], "received": 0}
    elif wrong == "sample":
        state["histories"]["src"]["samples"] = [[0.5, draw(st.sampled_from([[0.5], [0.5, 1.0], [0.5, 1, 2], ["a", 1]]))]]
    return state


def _write_folder(run: Path, state: dict, states: dict[str, bytes], wrong: str | None, draw) -> Path:
    """The folder checkpoints.write makes, holding ``state`` (the manifest re-written to match,
    as a hand that edits it would), then one thing done to it (``wrong``, one of _FOLDER_WRONGS)."""
    path = checkpoints.write(run, 7, {"t": 0.0}, states, "h")
    manifest = json.loads((path / checkpoints.MANIFEST).read_text())
    server = path / checkpoints.SERVER_FILE
    data = msgpack.packb(state, use_bin_type=True)
    server.write_bytes(data)
    manifest["files"][checkpoints.SERVER_FILE] = {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}
    if wrong == "manifest":
        lacking = draw(st.sampled_from(["files", "nodes"]))
        (path / checkpoints.MANIFEST).write_text(draw(st.text(max_size=30) | deep_json | st.just(json.dumps(
            {k: v for k, v in manifest.items() if k != lacking}))))
        return path
    if wrong == "size":
        manifest["files"][checkpoints.SERVER_FILE]["size"] += draw(st.sampled_from([-1, 1]))
    elif wrong == "sha256":
        manifest["files"][draw(st.sampled_from(sorted(manifest["files"])))]["sha256"] = "0" * 64
    elif wrong == "file name":
        manifest["files"][draw(st.sampled_from(["../g.state", "/etc/hosts", ".", "a/b", "\x00"]))] = \
            {"size": 0, "sha256": hashlib.sha256(b"").hexdigest()}
    elif wrong == "config":
        manifest["config_sha256"] = "other"
    elif wrong == "state missing":
        manifest["nodes"].append("src")
    elif wrong in ("truncated", "not msgpack"):
        data = server.read_bytes()[:-1] if wrong == "truncated" else b"\xc1" + server.read_bytes()
        server.write_bytes(data)  # and the manifest re-written to match: only the content tells
        manifest["files"][checkpoints.SERVER_FILE] = {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}
    (path / checkpoints.MANIFEST).write_text(json.dumps(manifest))
    return path


@pytest.fixture(scope="module")
def fit_project(tmp_path_factory):
    from hycosim.core.config import load_project

    tmp = tmp_path_factory.mktemp("fit")
    cfg = write_project(tmp / "p.json", _FIT_NODES, [{"from": "src.a", "to": "g.u"}], events=_FIT_EVENTS,
                        cosim={"stepSize": 0.01, "stopTime": 2.0})
    return load_project(cfg).project


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture], max_examples=40)
@pytest.mark.parametrize("wrong", [None, *_FOLDER_WRONGS, *_STATE_WRONGS])
@given(data=st.data())
def test_a_checkpoint_is_taken_back_whole_or_refused_naming_it(tmp_path, fit_project, wrong, data):
    """A checkpoint folder as the relay writes it is read back as written; one with anything
    wrong in its files, its server state's shape or its fit to the project is refused, naming
    the folder, and the one before it is used. Before, a state of the right shape but not the
    project's (a string where a Real goes, a mode or event it does not have, a time outside the
    run) was restored and ended the run in a timeout, and ``"disarmed": [["hold"]]`` in a
    TypeError; reading alone let a NaN time and a negative j through."""
    run = tmp_path / "run"
    shutil.rmtree(run, ignore_errors=True)
    run.mkdir()
    state = data.draw(_server_states(wrong if wrong in _STATE_WRONGS else None))
    states = {"g": data.draw(st.binary(max_size=40))}
    path = _write_folder(run, state, states, None if wrong in _STATE_WRONGS else wrong, data.draw)
    if wrong is None or _STATE_WRONGS.get(wrong) == "fit":
        cp = checkpoints.read(path, "h")  # the shape is right
        assert cp.step == state["step"]
        assert cp.server == {**state, "t": float(state["t"]), "origin": float(state["origin"]),
                             "h": float(state["h"])} and cp.states == states
    if wrong is None:
        cp = checkpoints.read(path, "h", fit_project)
        assert cp.server["outputs"] == state["outputs"] and cp.states == states
        return
    with pytest.raises(checkpoints.CheckpointError) as exc:
        checkpoints.read(path, "h", fit_project)
    assert str(path) in str(exc.value)
    if _STATE_WRONGS.get(wrong) == "fit":
        assert "does not fit the project" in str(exc.value)
    # The newer checkpoint is passed over, naming why, for a good one before it.
    checkpoints.write(run, 3, data.draw(_server_states(None)), states, "h")
    cp, passed = checkpoints.latest(run, "h", project=fit_project)
    assert cp is not None and cp.path.name == "3" and passed == [str(exc.value)]
