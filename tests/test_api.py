"""hycosim.open: a run driven from Python, point by point, is the run `hycosim run` makes."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

import hycosim
from tests.helpers import REPO, hycosim as cli, meta, read_rows


def _catch(tmp_path: Path) -> Path:
    """The shipped default project without its asynchronous sensor (which one process cannot
    host): a pendulum caught by a hand (an event, guards, a mode switch), a gain chain."""
    doc = json.loads((REPO / "hycosim" / "configs" / "default.json").read_text())
    doc.pop("$schema")
    doc["nodeLists"] = [n for n in doc["nodeLists"] if n["nodeName"] not in ("sensor", "sensed")]
    doc["linkLists"] = [ln for ln in doc["linkLists"] if not {"sensor", "sensed"} & {ln["from"].split(".")[0],
                                                                                    ln["to"].split(".")[0]}]
    doc["nodeNum"], doc["linkNum"] = len(doc["nodeLists"]), len(doc["linkLists"])
    path = tmp_path / "catch.json"
    path.write_text(json.dumps(doc, indent=1))
    return path


def test_a_run_driven_to_its_stop_time_writes_what_hycosim_run_writes(tmp_path):
    project = _catch(tmp_path)
    stop = json.loads(project.read_text())["coSimulation"]["stopTime"]
    with hycosim.open(project, runs_dir=tmp_path / "api") as sim:
        assert (sim.time, sim.step_count) == (0.0, 0)
        assert sim.step() == pytest.approx(sim.time) and sim.step_count == 1
        half = sim.run_until(stop / 2)
        assert half == pytest.approx(stop / 2) and sim.time == half
        assert sim.run_until(stop / 4) == half  # a time already passed: nothing is taken again
        while not sim.ended:
            sim.step()
        assert sim.time == pytest.approx(stop)
    assert sim.outcome.status == "completed" and sim.outcome.code == 0
    for mode in ("--in-process", "--processes"):
        res = cli("run", str(project), mode, "--no-progress", "--runs-dir", str(tmp_path / mode))
        assert res.returncode == 0, res.stderr
        run = next((tmp_path / mode).iterdir())
        assert (run / "values.csv").read_bytes() == (sim.run_dir / "values.csv").read_bytes(), mode
    assert (sim.run_dir / "events.jsonl").read_text().count('"to": "grasp"') == 1


def test_get_reads_the_point_the_run_stands_at_as_its_row_records_it(tmp_path):
    project = _catch(tmp_path)
    seen = []
    with hycosim.open(project, runs_dir=tmp_path / "runs") as sim:
        for _ in range(30):
            seen.append((sim.step_count, sim.get("pendulum.theta"), sim.get("delayed.u"), sim.get("hand.y")))
            sim.step()
    rows = read_rows(sim.run_dir)
    for k, angle, routed, hand in seen:
        assert float(rows[k]["pendulum.theta"]) == pytest.approx(angle, abs=1e-12)
        assert float(rows[k]["delayed.u"]) == pytest.approx(routed, abs=1e-12)
        assert float(rows[k]["hand.y"]) == pytest.approx(hand, abs=1e-12)
    assert len({a for _, a, _, _ in seen}) > 20  # it swings: the values are the points', not one


def test_leaving_the_block_early_stops_the_run_and_keeps_its_rows(tmp_path):
    project = _catch(tmp_path)
    with hycosim.open(project, runs_dir=tmp_path / "runs") as sim:
        sim.run_until(0.3)
        at = sim.step_count
    assert sim.outcome.status == "stopped" and "stopped after" in sim.outcome.message
    assert meta(sim.run_dir)["status"] == "stopped"
    assert len(read_rows(sim.run_dir)) == at + 1  # every point up to where it stood
    with pytest.raises(hycosim.ClosedError, match="closed"):
        sim.step()
    with pytest.raises(hycosim.ClosedError):
        sim.get("pendulum.theta")
    sim.close()  # a second close does nothing


def test_what_the_api_refuses_is_named_by_one_class(tmp_path):
    doc = {"projectName": "chain", "nodeNum": 2, "linkNum": 1,
           "nodeLists": [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
                         {"nodeName": "g", "UID": 2, "model": "gain", "parameters": {"k": 2.0}, "input": ["u"],
                          "output": ["y"]}],
           "linkLists": [{"from": "clock.y", "to": "g.u"}], "coSimulation": {"stepSize": 0.1, "stopTime": 0.5}}
    with hycosim.open(doc, runs_dir=tmp_path / "runs") as sim:  # a project as a dict
        for call, error, says in ((lambda: sim.run_until(0.6), hycosim.TimeError, "past the stop time"),
                                  (lambda: sim.run_until(float("nan")), hycosim.TimeError, "not a finite time"),
                                  (lambda: sim.get("g.x"), hycosim.PortError, "did you mean 'g.y'"),
                                  (lambda: sim.get(3), hycosim.PortError, "no port")):
            with pytest.raises(error, match=says):
                call()
            assert issubclass(error, hycosim.SimulationError)
        sim.run_until(0.5)
        assert sim.ended and sim.get("g.y") == pytest.approx(2 * sim.get("g.u") - 0.0, abs=0.3)
        with pytest.raises(hycosim.TimeError, match="over"):
            sim.step()
    bad = dict(doc, linkLists=[{"from": "clock.nope", "to": "g.u"}])
    with pytest.raises(hycosim.ProjectError, match="clock.nope is not an output"):
        hycosim.open(bad, runs_dir=tmp_path / "runs")
    with pytest.raises(hycosim.ProjectError, match="no-such-file.json"):
        hycosim.open(tmp_path / "no-such-file.json")


_FAILS = """
from hycosim.node.reference.gain import Gain


class FailsLater(Gain):
    def step(self, t, h, inputs):
        if t >= 0.25:
            raise RuntimeError("the model gave up")
        super().step(t, h, inputs)
"""


def test_a_run_that_fails_raises_run_failed_and_keeps_its_records(tmp_path):
    (tmp_path / "fails.py").write_text(_FAILS)
    project = tmp_path / "p.json"
    project.write_text(json.dumps({
        "projectName": "fails", "nodeNum": 2, "linkNum": 1,
        "nodeLists": [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
                      {"nodeName": "g", "UID": 2, "model": "fails.py:FailsLater", "input": ["u"], "output": ["y"]}],
        "linkLists": [{"from": "clock.y", "to": "g.u"}], "coSimulation": {"stepSize": 0.1, "stopTime": 1.0}}))
    with hycosim.open(project, runs_dir=tmp_path / "runs") as sim:
        sim.step()
        with pytest.raises(hycosim.RunFailed, match="the model gave up"):
            sim.run_until(1.0)
    assert sim.outcome.status == "failed" and sim.outcome.code == 3
    assert len(read_rows(sim.run_dir)) >= 3 and meta(sim.run_dir)["status"] == "failed"


def test_import_hycosim_stays_light():
    res = subprocess.run([sys.executable, "-X", "importtime", "-c", "import hycosim; hycosim.__doc__"],
                         capture_output=True, text=True, cwd=REPO, timeout=60)
    imported = {line.rsplit("|", 1)[-1].strip() for line in res.stderr.splitlines() if "|" in line}
    assert "hycosim" in imported and not {m for m in imported if m.startswith(("hycosim.", "zenoh", "fmpy"))}, imported
    res = subprocess.run([sys.executable, "-c", "import hycosim, sys; hycosim.open; print('hycosim.api' in sys.modules)"],
                         capture_output=True, text=True, cwd=REPO, timeout=60)
    assert res.stdout.strip() == "True", res.stderr


def test_a_distributed_run_driven_from_python_writes_what_hycosim_run_writes(tmp_path):
    """distributed=True: the master in this process, each node a process over Zenoh."""
    project = _catch(tmp_path)
    with hycosim.open(project, runs_dir=tmp_path / "api", distributed=True) as sim:
        sim.run_until(1.0)
        angle = sim.get("pendulum.theta")
        sim.run_until(json.loads(project.read_text())["coSimulation"]["stopTime"])
    assert sim.outcome.status == "completed", sim.outcome
    run = sim.run_dir
    assert meta(run)["endpoint"].startswith("tcp/127.0.0.1:") and (run / "node-pendulum.log.jsonl").is_file()
    assert float(read_rows(run)[round(1.0 / 0.01)]["pendulum.theta"]) == pytest.approx(angle, abs=1e-12)
    res = cli("run", str(project), "--processes", "--no-progress", "--runs-dir", str(tmp_path / "cli"))
    assert res.returncode == 0, res.stderr
    assert (next((tmp_path / "cli").iterdir()) / "values.csv").read_bytes() == (run / "values.csv").read_bytes()


def test_a_distributed_run_of_a_dict_left_early_is_stopped_and_its_nodes_are_gone(tmp_path):
    doc = {"projectName": "chain", "nodeNum": 2, "linkNum": 1,
           "nodeLists": [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
                         {"nodeName": "g", "UID": 2, "model": "gain", "parameters": {"k": 2.0}, "input": ["u"],
                          "output": ["y"]}],
           "linkLists": [{"from": "clock.y", "to": "g.u"}], "coSimulation": {"stepSize": 0.1, "stopTime": 5.0}}
    with hycosim.open(doc, runs_dir=tmp_path / "runs", distributed=True) as sim:
        sim.run_until(0.5)
        sim.override("g.u", 3.0)
        sim.step()
        assert sim.get("g.y") == 6.0
    assert sim.outcome.status == "stopped" and len(read_rows(sim.run_dir)) == 7
    assert json.loads((sim.run_dir / "project.json").read_text()) == doc
    for name in ("clock", "g"):
        assert "finished after" in (sim.run_dir / f"node-{name}.stderr.txt").read_text()
    with pytest.raises(hycosim.ProjectError, match="node 'g'"):
        hycosim.open(dict(doc, nodeLists=[doc["nodeLists"][0], dict(doc["nodeLists"][1], model="gian")]),
                     runs_dir=tmp_path / "bad", distributed=True)
    assert not (tmp_path / "bad").exists()  # refused before a run directory is made


def test_a_dict_names_its_files_from_the_current_folder_in_processes_too(tmp_path, monkeypatch):
    (tmp_path / "twice.py").write_text("from hycosim.node.reference.gain import Gain\n\n\nclass Twice(Gain):\n"
                                       "    def setup(self, ctx):\n        super().setup(ctx)\n        self.k = 2.0\n")
    monkeypatch.chdir(tmp_path)
    doc = {"projectName": "files", "nodeNum": 2, "linkNum": 1,
           "nodeLists": [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
                         {"nodeName": "g", "UID": 2, "model": "twice.py:Twice", "input": ["u"], "output": ["y"]}],
           "linkLists": [{"from": "clock.y", "to": "g.u"}], "coSimulation": {"stepSize": 0.1, "stopTime": 0.3}}
    for distributed in (False, True):
        with hycosim.open(doc, runs_dir=tmp_path / f"runs-{distributed}", distributed=distributed) as sim:
            sim.run_until(0.3)
            assert sim.get("g.y") == pytest.approx(0.4)
        assert sim.outcome.status == "completed", (distributed, sim.outcome)


class _Counting:
    """A user's observer: any object with the three methods."""

    def __init__(self):
        self.points, self.ended = [], None

    def step_complete(self, step, t, values):
        self.points.append((step, values["g.u"], values["clock.y"]))

    def state_restored(self, step, t):
        raise AssertionError("nothing is restored in this run")

    def run_ended(self, status):
        self.ended = status


def test_observers_see_every_point_as_values_csv_records_it(tmp_path):
    project = _catch(tmp_path)
    series, last = hycosim.TimeSeries(["pendulum.theta", "delayed.u", "hand.y"]), hycosim.LastValues()
    with hycosim.open(project, runs_dir=tmp_path / "runs") as sim:
        sim.add_observer(series)
        sim.run_until(0.5)
        sim.add_observer(last)
        sim.run_until(json.loads(project.read_text())["coSimulation"]["stopTime"])
    rows = read_rows(sim.run_dir)
    assert series.steps == [int(r["step"]) for r in rows] and series.t == [float(r["t"]) for r in rows]
    for port in series.ports:
        assert series.values[port] == [float(r[port]) for r in rows], port
    assert last.step == int(rows[-1]["step"]) and last.values["pendulum.theta"] == float(rows[-1]["pendulum.theta"])
    with pytest.raises(hycosim.SimulationError, match="is no observer: it lacks step_complete"):
        with hycosim.open(project, runs_dir=tmp_path / "other") as sim:
            sim.add_observer(object())


def test_a_users_observer_hears_the_end_and_one_that_fails_ends_the_run_named(tmp_path):
    doc = {"projectName": "chain", "nodeNum": 2, "linkNum": 1,
           "nodeLists": [{"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
                         {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]}],
           "linkLists": [{"from": "clock.y", "to": "g.u"}], "coSimulation": {"stepSize": 0.1, "stopTime": 0.5}}
    counting = _Counting()
    with hycosim.open(doc, runs_dir=tmp_path / "runs") as sim:
        sim.add_observer(counting)
        sim.run_until(0.5)
    assert counting.ended == "completed" and [k for k, _, _ in counting.points] == list(range(6))
    assert all(u == pytest.approx(y) for _, u, y in counting.points)  # an input as routed at its point

    class Broken(_Counting):
        def step_complete(self, step, t, values):
            if step == 2:
                raise ValueError("cannot keep up")

    broken = Broken()
    with hycosim.open(doc, runs_dir=tmp_path / "broken") as sim:
        sim.add_observer(broken)
        with pytest.raises(hycosim.RunFailed, match="observer Broken: step_complete failed at step 2.*cannot keep up"):
            sim.run_until(0.5)
    assert broken.ended == "failed" and len(read_rows(sim.run_dir)) >= 3


class _OwnRecorder:
    """A recorder of a user's own, written against the observer protocol as hycosim's recorder
    is: the point whole (mode, each node's lists, how the step went), not port by port."""

    def __init__(self):
        self.rows, self.timing, self.ended = [], [], None

    def step_complete(self, step, t, point):
        cells = [step, t, point.mode]
        for side in (point.outputs, point.inputs):
            for values in side.values():
                for value in values:
                    cells.extend(value if isinstance(value, list) else [value])
        self.rows.append(cells)
        self.timing.append((step, point.holder, sorted(point.arrivals), point.takes))

    def state_restored(self, step, t):
        raise AssertionError("nothing is restored in this run")

    def run_ended(self, status):
        self.ended = status


def test_a_users_recorder_sees_each_point_whole_as_the_recorder_writes_it(tmp_path):
    project = _catch(tmp_path)
    own = _OwnRecorder()
    with hycosim.open(project, runs_dir=tmp_path / "runs") as sim:
        sim.add_observer(own)
        sim.run_until(json.loads(project.read_text())["coSimulation"]["stopTime"])
    assert own.ended == "completed"
    with open(sim.run_dir / "values.csv", newline="") as f:
        table = list(csv.reader(f))[1:]
    assert len(own.rows) == len(table) > 10
    for mine, row in zip(own.rows, table):
        assert [mine[0], mine[1], mine[2]] == [int(row[0]), float(row[1]), row[2]]
        assert [float(v) for v in mine[3:]] == [float(c) for c in row[3:]], row[0]
    with open(sim.run_dir / "timing.csv", newline="") as f:
        timing = list(csv.DictReader(f))
    assert [(k, holder) for k, holder, _, _ in own.timing] == [(int(r["step"]), r["holder"]) for r in timing]
    stepping = sorted(c.split(":", 1)[1] for c in timing[0] if c.startswith("arrival_s:"))
    assert all(arrived == stepping for _, _, arrived, _ in own.timing[1:])  # every release's answers


def test_a_time_series_drops_what_a_rollback_takes_again():
    series = hycosim.TimeSeries(["a.y"])
    for k in range(6):
        series.step_complete(k, k * 0.1, {"a.y": float(k)})
    series.state_restored(3, 0.3)
    assert series.steps == [0, 1, 2] and series.values["a.y"] == [0.0, 1.0, 2.0] and len(series.t) == 3


def test_the_callers_structlog_setup_is_put_back_when_the_run_ends(tmp_path):
    import structlog

    mine = [structlog.processors.KeyValueRenderer()]
    structlog.configure(processors=mine)
    try:
        with hycosim.open(_catch(tmp_path), runs_dir=tmp_path / "runs") as sim:
            assert structlog.get_config()["processors"] is not mine  # the run's, meanwhile
            sim.step()
        assert structlog.get_config()["processors"] is mine
        assert "step" in (sim.run_dir / "server.log.jsonl").read_text()
    finally:
        structlog.reset_defaults()


_PEAK = """
import json
from pathlib import Path


class Peak:
    def __init__(self, port, out):
        self.port, self.out, self.highest, self.points = port, Path(out), float("-inf"), 0

    def step_complete(self, step, t, values):
        self.highest, self.points = max(self.highest, values[self.port]), self.points + 1

    def state_restored(self, step, t):
        pass

    def run_ended(self, status):
        self.out.write_text(json.dumps({"highest": self.highest, "points": self.points, "status": status}))
"""


def test_an_observer_named_in_the_project_file_sees_every_run_it_is_in(tmp_path):
    (tmp_path / "peak.py").write_text(_PEAK)
    doc = json.loads(_catch(tmp_path).read_text())
    for mode in ("--processes", "--in-process"):
        doc["observers"] = [{"observer": "peak.py:Peak",
                             "parameters": {"port": "pendulum.theta", "out": str(tmp_path / f"peak{mode}.json")}}]
        project = tmp_path / "observed.json"
        project.write_text(json.dumps(doc))
        res = cli("run", str(project), mode, "--no-progress", "--runs-dir", str(tmp_path / mode))
        assert res.returncode == 0, res.stderr
        rows = read_rows(next((tmp_path / mode).iterdir()))
        said = json.loads((tmp_path / f"peak{mode}.json").read_text())
        assert said == {"highest": max(float(r["pendulum.theta"]) for r in rows), "points": len(rows),
                        "status": "completed"}, mode
    for entry, says in (({"observer": "peak.py:Nope"}, "has no attribute 'Nope'"),
                        ({"observer": "peak.py:Peak"}, "missing 2 required positional arguments"),
                        ({"observer": "json:JSONDecoder"}, "is no observer: it lacks step_complete")):
        doc["observers"] = [entry]
        project.write_text(json.dumps(doc))
        for args in (("validate",), ("run", "--runs-dir", str(tmp_path / "bad"))):
            res = cli(*args[:1], str(project), *args[1:])
            assert res.returncode == 2 and "observers[0]" in res.stderr and says in res.stderr, (args, res.stderr)
            assert "Traceback" not in res.stderr and not (tmp_path / "bad").exists()


def test_an_ssp_package_runs_as_hycosim_run_runs_it_and_a_bad_one_is_named(tmp_path):
    from benchmarks._small_fmus import write_package

    _, package = write_package(tmp_path / "fmus", 30)
    with hycosim.open(package, runs_dir=tmp_path / "api") as sim:
        sim.run_until(0.3)
    assert sim.outcome.status == "completed"
    res = cli("run", str(package), "--in-process", "--no-progress", "--runs-dir", str(tmp_path / "cli"))
    assert res.returncode == 0, res.stderr
    assert (next((tmp_path / "cli").iterdir()) / "values.csv").read_bytes() == (sim.run_dir / "values.csv").read_bytes()
    (tmp_path / "broken.ssp").write_bytes(b"not a zip")
    with pytest.raises(hycosim.ProjectError, match="broken.ssp"):
        hycosim.open(tmp_path / "broken.ssp", runs_dir=tmp_path / "bad")
    assert not (tmp_path / "bad").exists()
