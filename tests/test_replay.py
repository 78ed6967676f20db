"""Replaying a recorded node (``"replay": RUN_DIR``): real runs, then the same with one node played back."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from hycosim.node.loader import NodeLoadError, check_node
from hycosim.node.replay import SamplePlayer
from hycosim.core.schema import CoSimulation, Node
from hycosim.core.recordings import Recording, RecordingError, Sample, encode_sample
from hycosim.scenario.scene_fmus import build_scene_fmus
from tests.helpers import REPO, hycosim, meta, read_rows, run_killing, run_project
from tests.wire_strategies import deep_json


def _with_replay(src: Path, dst: Path, node: str, run_dir: Path | str, **cosim) -> Path:
    doc = json.loads(src.read_text())
    for n in doc["nodeLists"]:
        if n["nodeName"] == node:
            n["replay"] = str(run_dir)
    doc["coSimulation"].update(cosim)
    dst.write_text(json.dumps(doc, indent=1))
    return dst


@pytest.fixture(scope="module")
def grasp_run(tmp_path_factory) -> tuple[Path, Path]:
    """The reference grasp (rod, robot scene, controller: Python nodes), run once: (project, run)."""
    tmp = tmp_path_factory.mktemp("grasp")
    cfg = tmp / "grasp.json"
    doc = json.loads((REPO / "hycosim" / "scenario" / "configs" / "grasp.json").read_text())
    doc["coSimulation"]["stopTime"] = 2.0
    cfg.write_text(json.dumps(doc))
    return cfg, run_project(cfg, tmp / "runs")


def test_a_replayed_stepping_node_gives_the_recorded_run_and_ends_where_its_recording_does(grasp_run, tmp_path):
    cfg, run = grasp_run
    replayed = _with_replay(cfg, tmp_path / "replay.json", "robot", run)
    again = run_project(replayed, tmp_path / "runs")
    assert (again / "values.csv").read_bytes() == (run / "values.csv").read_bytes()
    assert (again / "events.jsonl").read_text().count('"to": "grasp"') == 1  # the grasp, from the played robot
    # A longer run than the recording: it ends cleanly where the recording does, naming it.
    longer = _with_replay(cfg, tmp_path / "longer.json", "robot", run, stopTime=3.0)
    ended = run_project(longer, tmp_path / "runs-longer")
    m = meta(ended)
    assert m["ended_by"]["node"] == "robot" and m["ended_by"]["t"] == pytest.approx(2.0)
    assert f"its recording in {run} ends at t=2 s" in m["ended_by"]["message"]
    assert len(read_rows(ended)) == len(read_rows(run))


def test_a_grasp_trial_with_its_camera_replayed_reproduces_the_trials_values(tmp_path):
    """The paper's scenario (rod and robot FMUs, policy, camera at 60 Hz, paced by the wall clock):
    played back, the camera gives the same samples at the same points, so every value matches."""
    fmus = build_scene_fmus(tmp_path / "build" / "fmus")
    doc = json.loads((REPO / "hycosim" / "scenario" / "configs" / "grasp-paper.json").read_text())
    doc["coSimulation"]["stopTime"] = 1.5
    for n in doc["nodeLists"]:
        if n.get("fmu"):
            n["fmu"] = str(fmus[n["nodeName"]])
        if n["nodeName"] == "policy":  # its inference time is a wall-clock measurement: left out
            n["output"] = [p for p in n["output"] if (p if type(p) is str else p["name"]) != "infer_ms"]
    cfg = tmp_path / "paper.json"
    cfg.write_text(json.dumps(doc))
    trial = run_project(cfg, tmp_path / "runs", timeout=180)
    rows = read_rows(trial)
    assert '"to": "grasp"' in (trial / "events.jsonl").read_text()
    measured = {r["rod.meas_angle"] for r in rows}
    assert len(measured) > 20  # the camera's samples reached the rod all along
    samples = (trial / "samples.jsonl").read_text().splitlines()
    assert len(samples) > 40 and all(json.loads(s)["node"] == "camera" for s in samples)

    # Played back, with the player's process killed once on the way (it is started again, and the
    # new one goes on from the release the server sends it): the trial as it was.
    replayed = _with_replay(cfg, tmp_path / "replayed.json", "camera", trial)
    assert hycosim("validate", str(replayed)).returncode == 0
    code, err = run_killing(replayed, tmp_path / "runs-replayed", [("node camera", 60)])
    assert code == 0, err
    again = next((tmp_path / "runs-replayed").iterdir())
    assert (again / "values.csv").read_bytes() == (trial / "values.csv").read_bytes()
    assert [(r["node"], r["cause"]) for r in meta(again)["recoveries"]] == [("camera", "restarted")]
    assert json.loads((again / "samples.jsonl").read_text().splitlines()[-1]) == json.loads(samples[-1])


def test_validate_refuses_recordings_that_do_not_fit_the_node(grasp_run, tmp_path):
    cfg, run = grasp_run
    cosim = CoSimulation(stepSize=0.01, stopTime=2.0)
    spec = json.loads(cfg.read_text())["nodeLists"][1]  # the robot

    def refused(entry: dict, cosim: CoSimulation = cosim, where: Path = run) -> str:
        node = Node.model_validate({**entry, "replay": str(where)})
        with pytest.raises(NodeLoadError) as info:
            check_node(node, tmp_path, cosim)
        return str(info.value)

    check_node(Node.model_validate({**spec, "replay": str(run)}), tmp_path, cosim)  # it fits as it was
    assert "it stepped 0.01 s, this project 0.02 s" in refused(spec, CoSimulation(stepSize=0.02))
    assert "it started at 0 s, this project at 1 s" in refused(spec, CoSimulation(startTime=1.0, stopTime=2.0))
    more = {**spec, "output": [*spec["output"], "wrist_torque"]}
    assert "it recorded no output 'wrist_torque' of 'robot'" in refused(more)
    retyped = {**spec, "output": [{"name": "dist", "type": "Integer"}]}
    assert "output robot.dist was Real there, Integer here" in refused(retyped)
    assert "'robot' was not asynchronous there" in refused({**spec, "input": [], "async": True})
    assert "has no node 'gripper'" in refused({**spec, "nodeName": "gripper"})
    assert "is not a folder" in refused(spec, where=tmp_path / "nowhere")
    # A recording whose values cannot be read: the file and the line.
    broken = tmp_path / "broken"
    shutil.copytree(run, broken)
    lines = (broken / "values.csv").read_text().splitlines(keepends=True)
    header = lines[0].rstrip("\n").split(",")
    cells = lines[5].rstrip("\n").split(",")
    cells[header.index("robot.dist")] = "far"
    lines[5] = ",".join(cells) + "\n"
    (broken / "values.csv").write_text("".join(lines))
    assert f"{broken / 'values.csv'}: line 6: could not convert string to float: 'far'" in refused(spec, where=broken)
    # Through the CLI: exit 2, the project file and the node's entry named.
    bad = _with_replay(cfg, tmp_path / "bad.json", "robot", run, stepSize=0.005)
    res = hycosim("validate", str(bad))
    assert res.returncode == 2
    assert f"{bad}: nodeLists[1]: node 'robot': replay: the run in {run} does not fit node 'robot'" in res.stderr


def test_a_sample_player_sends_each_sample_once_before_the_point_it_was_first_had_at():
    samples = [Sample(0, 0.0, [1.0]), Sample(3, 0.02, [2.0]), Sample(3, 0.031, [3.0]), Sample(7, 0.05, [4.0])]
    player = SamplePlayer(samples)
    assert player.due(-1, 0) == samples[:1]
    assert player.due(0, 2) == []
    assert player.due(2, 3) == samples[1:3]
    assert player.due(3, 3) == []  # a retried step sends nothing again
    assert player.due(3, 100) == samples[3:]


# --- the recording reader is total: a user's files --------------------------------------------

_NODE = Node.model_validate({"nodeName": "cam", "UID": 1, "async": True,
                             "output": ["a", {"name": "ok", "type": "Boolean"}, {"name": "n", "type": "Integer"},
                                        {"name": "raw", "type": "Binary"}]})
_VALID = st.tuples(st.floats(allow_nan=False, width=64), st.booleans(), st.integers(-2**40, 2**40),
                   st.binary(max_size=8))
_JUNK = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=6),
                  st.lists(st.integers(), max_size=3), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))


@st.composite
def _sample_lines(draw) -> str:
    """A samples.jsonl: mostly well-formed lines, some with one part broken, some not JSON at all."""
    lines, point = [], 0
    for _ in range(draw(st.integers(0, 6))):
        point += draw(st.integers(0, 3))
        t = draw(st.floats(0, 100))
        values = list(draw(_VALID))
        how = draw(st.sampled_from(["ok", "ok", "ok", "value", "point", "t", "width", "node", "text", "torn", "deep"]))
        if how == "value":
            values[draw(st.integers(0, 3))] = draw(_JUNK | st.integers(-10 ** 400, 10 ** 400))
        line = encode_sample("cam" if how != "node" else draw(st.sampled_from(["other", ""])), point, t, values)
        record = json.loads(line)
        if how == "point":
            record["point"] = draw(_JUNK)
        elif how == "t":
            record["t"] = draw(st.one_of(_JUNK, st.just(float("inf"))))
        elif how == "width":
            record["values"] = values[:draw(st.integers(0, 3))]
        line = json.dumps(record) + "\n" if how not in ("text", "torn") else line
        if how == "deep":  # JSON nested deeper than Python's decoder recurses, or not quite
            line = draw(deep_json) + "\n"
        elif how == "text":
            line = draw(st.text(max_size=20)).replace("\n", " ") + "\n"
        elif how == "torn":
            line = line[:draw(st.integers(0, len(line) - 2))]
        lines.append(line)
    return "".join(lines)


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=_sample_lines())
@example(text='{"node": "cam", "point": 0, "t": 0.0, "values": [0, false, 0, ""]}\n')  # a whole Real, as JSON writes it
@example(text='{"node": "cam", "point": 0, "t": 0.0, "values": [1%s, false, 0, ""]}\n' % ("0" * 400))  # no float
def test_samples_read_from_any_file_are_checked_or_refused_by_name(tmp_path, text):
    project = {"projectName": "p", "nodeNum": 1, "nodeLists": [_NODE.model_dump(by_alias=True)]}
    (tmp_path / "project.json").write_text(json.dumps(project))
    (tmp_path / "samples.jsonl").write_text(text)
    try:
        samples = Recording(tmp_path).samples(_NODE)
    except RecordingError as exc:
        assert str(tmp_path / "samples.jsonl") in str(exc)
        return
    for s in samples:  # what is read is what the node may send: typed, finite times, points in order
        assert type(s.values[0]) is float and type(s.values[1]) is bool and type(s.values[2]) is int
        assert type(s.values[3]) in (bytes, list) and math.isfinite(s.t)
    assert [s.point for s in samples] == sorted(s.point for s in samples)


_PROJECT = json.dumps({"projectName": "p", "nodeNum": 1,
                       "nodeLists": [{"nodeName": "n", "UID": 1, "output": ["y"]}]})


@st.composite
def _values_csv(draw) -> str:
    """A values.csv: the right header or one missing the column, rows of numbers in order, some
    with a cell broken, a time going back, a cell too few, or a torn end."""
    header = draw(st.sampled_from(["step,t,mode,n.y", "step,t,mode,n.x", "step,t,mode,n.y,m.z"]))
    width = header.count(",") + 1
    lines, t = [header], 0.0
    for k in range(draw(st.integers(0, 5))):
        t += draw(st.sampled_from([0.01, 0.01, 0.0, -0.01]))
        cells = [str(k), repr(t), "free", *(repr(draw(st.floats(allow_nan=False))) for _ in range(width - 3))]
        how = draw(st.sampled_from(["ok", "ok", "ok", "cell", "short", "t"]))
        if how == "cell":
            cells[draw(st.integers(1, width - 1))] = draw(st.text(max_size=5)).replace("\n", "")
        elif how == "short":
            cells.pop()
        elif how == "t":
            cells[1] = draw(st.sampled_from(["nan", "inf", "", "x"]))
        lines.append(",".join(cells))
    text = "\n".join(lines) + "\n"
    return text[:draw(st.integers(0, len(text)))] if draw(st.booleans()) else text


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(project=st.one_of(st.just(_PROJECT), st.binary(max_size=40).map(lambda b: b.decode("latin-1")),
                         st.dictionaries(st.sampled_from(["projectName", "nodeNum", "nodeLists", "x"]), _JUNK,
                                         max_size=4).map(json.dumps)),
       values=_values_csv())
def test_any_run_directory_is_read_or_refused_with_a_reason(tmp_path, project, values):
    (tmp_path / "project.json").write_text(project)
    (tmp_path / "values.csv").write_text(values)
    spec = Node.model_validate({"nodeName": "n", "UID": 1, "output": ["y"]})
    try:
        recording = Recording(tmp_path)
        recording.require_fit(spec, CoSimulation())
        rows = recording.outputs(spec)
    except RecordingError as exc:
        assert str(tmp_path) in str(exc)
        return
    assert rows and all(type(v[0]) in (float, int) for _, v in rows)
    assert all(a[0] < b[0] for a, b in zip(rows, rows[1:])) and all(math.isfinite(t) for t, _ in rows)
