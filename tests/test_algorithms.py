"""Master algorithms behind one interface: the built-in ones chosen once from the project, and
a user's, named in the project file by import path, taking every step of a run."""

from __future__ import annotations

from pathlib import Path

import pytest

from hycosim.core.config import load_project
from hycosim.master import checkpoints
from hycosim.master.algorithms import GaussSeidel, Iterated, Jacobi, Localised, StepControlled
from hycosim.master.algorithms.choice import project_algorithm
from tests.helpers import column, hycosim, meta, read_rows, write_project

EXTRAPOLATED = '''
from hycosim.master.algorithms import Algorithm, Jacobi, StepTaken


class ExtrapolatedJacobi(Algorithm):
    """Jacobi on each Real input extrapolated from the last two points to ``at`` of the step."""

    def __init__(self, at=1.0):
        self.at, self.jacobi, self.before = at, Jacobi(), None

    def step(self, barrier, request):
        now = {node: list(values) for node, values in barrier.inputs.items()}
        inputs = now
        if self.before is not None and request.t > self.before[0]:
            t0, old = self.before
            scale = self.at * request.h / (request.t - t0)
            inputs = {node: [b + (b - a) * scale if type(a) is type(b) is float else b
                             for a, b in zip(old[node], values)] for node, values in now.items()}
        self.before = (request.t, now)
        arrivals, wait = self.jacobi.take(barrier, request.k, request.t, request.h, request.mode,
                                          meanwhile=request.record, inputs=inputs)
        return StepTaken(request.h, arrivals, wait)

    def checkpoint(self):
        return {"before": list(self.before) if self.before else None}

    def restore(self, kept, barrier, what):
        self.before = tuple(kept["before"]) if kept.get("before") else None


class Broken(ExtrapolatedJacobi):
    def step(self, barrier, request):
        if request.k == 5:
            raise ZeroDivisionError("no step 5 here")
        return super().step(barrier, request)


class NoStep:
    def __init__(self, **kw):
        pass
'''

NODES = [{"nodeName": "ramp", "UID": 1, "model": "ramp", "parameters": {"b": 2.0}, "output": ["y", "v"]},
         {"nodeName": "gain", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]}]
LINKS = [{"from": "ramp.y", "to": "gain.u"}]


def _project(tmp_path: Path, name: str = "follow", **cosim) -> Path:
    (tmp_path / "extrapolated.py").write_text(EXTRAPOLATED)
    return write_project(tmp_path / f"{name}.json", NODES, LINKS, name=name,
                         cosim={"stepSize": 0.1, "stopTime": 2.0, **cosim})


def _run(cfg: Path, runs: Path, *args: str):
    res = hycosim("run", str(cfg), "--no-progress", "--runs-dir", str(runs), *args, timeout=180)
    run_dir = next(runs.iterdir()) if runs.is_dir() and any(runs.iterdir()) else None
    return res, run_dir


@pytest.mark.parametrize("mode", ["--in-process", "--processes"])
def test_a_users_algorithm_named_by_import_path_takes_every_step_of_the_run(tmp_path, mode):
    cfg = _project(tmp_path, algorithm="extrapolated.py:ExtrapolatedJacobi", algorithmParameters={"at": 1.0})
    res, run = _run(cfg, tmp_path / "runs", mode)
    assert res.returncode == 0, res.stderr
    rows = read_rows(run)
    ramp, gain = column(rows, "ramp.y"), column(rows, "gain.y")
    assert len(rows) == 21
    # From point 2 on, the gain stepped on its input extrapolated to the step's end: the ramp there.
    assert gain[2:] == pytest.approx(ramp[2:], abs=1e-12) and gain[1] == 0.0
    plain, plain_run = _run(_project(tmp_path, "plain"), tmp_path / "plain", mode)
    assert plain.returncode == 0, plain.stderr
    lagging = read_rows(plain_run)
    assert column(lagging, "gain.y")[1:] == pytest.approx(ramp[:-1], abs=1e-12)  # Jacobi: one step late
    # The record holds the inputs routed at each point, as for any algorithm.
    assert column(rows, "gain.u") == column(lagging, "gain.u")
    assert meta(run)["status"] == "completed"


def test_a_users_algorithm_keeps_its_own_state_in_each_checkpoint(tmp_path):
    cfg = _project(tmp_path, algorithm="extrapolated.py:ExtrapolatedJacobi", checkpointEvery=0.5)
    res, run = _run(cfg, tmp_path / "runs", "--processes")
    assert res.returncode == 0, res.stderr
    cp, passed = checkpoints.latest(run, meta(run)["config_sha256"])
    assert cp is not None and not passed
    kept = cp.server["algorithm"]["before"]
    step_before = cp.step - 1  # what the algorithm held at the checkpoint: the point before's inputs
    assert kept[0] == pytest.approx(0.1 * step_before)
    assert kept[1]["gain"] == [pytest.approx(2.0 * 0.1 * step_before)]


def test_a_users_algorithm_that_fails_ends_the_run_named_with_every_point_before_kept(tmp_path):
    cfg = _project(tmp_path, algorithm="extrapolated.py:Broken")
    res, run = _run(cfg, tmp_path / "runs", "--in-process")
    assert res.returncode == 3, res.stderr
    said = res.stdout + res.stderr
    assert "master algorithm Broken failed at step 5" in said and "ZeroDivisionError: no step 5 here" in said
    assert "Traceback" not in said
    assert [int(r["step"]) for r in read_rows(run)] == list(range(6))  # point 5 too: it stood when the step failed
    assert meta(run)["status"] == "failed"


@pytest.mark.parametrize("algorithm, parameters, says", [
    ("missing.py:ExtrapolatedJacobi", {}, "cannot be made: ImportError"),
    ("extrapolated.py:Nowhere", {}, "cannot be made: AttributeError"),
    ("extrapolated.py:NoStep", {}, "is no master algorithm: it lacks plan, step"),
    ("extrapolated.py:ExtrapolatedJacobi", {"speed": 3}, "cannot be made: TypeError"),
])
def test_an_algorithm_that_cannot_be_made_is_named_before_the_run(tmp_path, algorithm, parameters, says):
    cfg = _project(tmp_path, algorithm=algorithm, algorithmParameters=parameters)
    for command in (("validate", str(cfg)), ("run", str(cfg), "--no-progress", "--runs-dir", str(tmp_path / "r"))):
        res = hycosim(*command)
        assert res.returncode == 2, (command, res.stdout, res.stderr)
        said = res.stdout + res.stderr
        assert f"coSimulation.algorithm {algorithm!r}" in said and says in said and "Traceback" not in said
    assert not (tmp_path / "r").exists()  # refused before a run directory is made


def test_an_algorithm_takes_the_place_of_iteration_and_step_control(tmp_path):
    cfg = _project(tmp_path, algorithm="extrapolated.py:ExtrapolatedJacobi", iterate={"tolerance": 1e-6})
    res = hycosim("validate", str(cfg))
    assert res.returncode == 2 and "coSimulation.iterate" in res.stdout + res.stderr
    assert "takes the place of iterate" in res.stdout + res.stderr


@pytest.mark.parametrize("cosim, chosen", [
    ({}, [Jacobi]),
    ({"coupling": "gauss-seidel"}, [GaussSeidel]),
    ({"iterate": {"tolerance": 1e-6}}, [Iterated, Jacobi]),
    ({"stepControl": {"tolerance": 1e-3, "minStep": 0.01, "maxStep": 0.2}}, [StepControlled, Jacobi]),
    ({"eventTolerance": 1e-3}, [Localised, Jacobi]),
    ({"eventTolerance": 1e-3, "algorithm": "extrapolated.py:ExtrapolatedJacobi"}, [Localised, "ExtrapolatedJacobi"]),
])
def test_the_algorithm_is_chosen_once_where_the_project_is_loaded(tmp_path, cosim, chosen):
    algorithm = project_algorithm(load_project(_project(tmp_path, **cosim)))
    made = [type(algorithm)]
    for inner in ("inner", "coupling"):
        if hasattr(algorithm, inner):
            made.append(type(getattr(algorithm, inner)))
            break
    assert [m.__name__ for m in made] == [c if isinstance(c, str) else c.__name__ for c in chosen]


class _Barrier:
    """Just what plan() reads of a barrier: the metadata and the inputs' labels."""

    def __init__(self):
        self.meta: dict = {}
        self.input_labels = {"ramp": [], "gain": ["gain.u"]}


@pytest.mark.parametrize("cosim, key", [
    ({"iterate": {"tolerance": 1e-6}}, "iteration"),
    ({"stepControl": {"tolerance": 1e-3, "minStep": 0.01, "maxStep": 0.2}}, "step_control"),
    ({"eventTolerance": 1e-3}, "event_localisation"),
])
def test_an_algorithm_the_nodes_cannot_take_part_in_falls_back_to_its_coupling_saying_why(tmp_path, cosim, key):
    algorithm = project_algorithm(load_project(_project(tmp_path, **cosim)))
    barrier = _Barrier()
    able = {"ramp": {"rollback": True, "variableStep": True}, "gain": {"rollback": True, "variableStep": True}}
    assert algorithm.plan(able, barrier) is algorithm
    unable = {"ramp": able["ramp"], "gain": {"rollback": False}}
    planned = algorithm.plan(unable, barrier)
    assert type(planned) is Jacobi and "gain cannot get and set state" in barrier.meta[key]
