"""Steps taken again: iterative coupling and the error-controlled macro step, end to end over Zenoh."""

from __future__ import annotations

import csv
import math
import json
import re
from pathlib import Path

import pytest

from hycosim.core.config import parse_project
from hycosim.core.coupling import algebraic_loops
from hycosim.master.report import read_steps
from hycosim.master.retakes import StepSizer, input_change
from tests.helpers import column, hycosim, meta, read_rows, run_project, write_project


def _loop(tmp_path: Path, ka: float, kb: float, **cosim) -> Path:
    """a.y = ka·b.y + 1 and b.y = kb·a.y: two gains, each an output fed straight through."""
    return write_project(tmp_path / "loop.json", [
        {"nodeName": "a", "UID": 1, "model": "gain", "parameters": {"k": ka, "b": 1.0}, "input": ["u"], "output": ["y"]},
        {"nodeName": "b", "UID": 2, "model": "gain", "parameters": {"k": kb}, "input": ["u"], "output": ["y"]},
    ], [{"from": "a.y", "to": "b.u"}, {"from": "b.y", "to": "a.u"}],
        cosim={"stepSize": 0.1, "stopTime": 0.5, **cosim})


def _takes(run: Path) -> list[int]:
    with open(run / "timing.csv", newline="") as f:
        return [int(r["takes"]) for r in csv.DictReader(f)]


def test_iterative_coupling_solves_an_algebraic_loop_at_every_step_that_jacobi_takes_late(tmp_path):
    res = hycosim("validate", str(_loop(tmp_path, 0.5, 0.5)))
    assert res.returncode == 0
    assert "algebraic loop a.u → a.y → b.u → b.y → a.u: Jacobi coupling takes it a macro step late" in res.stderr

    cfg = _loop(tmp_path, 0.5, 0.5, iterate={"tolerance": 1e-10, "maxIterations": 50})
    res = hycosim("validate", str(cfg))
    assert res.returncode == 0 and "solved at each step by coSimulation.iterate" in res.stdout
    run = run_project(cfg, tmp_path / "i")
    rows = read_rows(run)
    a, b = column(rows, "a.y"), column(rows, "b.y")
    for k in range(1, len(rows)):  # a = 0.5·b + 1, b = 0.5·a: a = 4/3, b = 2/3 at every point
        assert a[k] == pytest.approx(4 / 3, rel=1e-8) and b[k] == pytest.approx(2 / 3, rel=1e-8), k
    takes = _takes(run)
    assert takes[0] == 1 and all(n > 2 for n in takes[1:2]) and max(takes) <= 50
    m = meta(run)
    assert m["iterations"]["not_converged"] == 0 and m["iterations"]["max_takes"] == max(takes)
    text = hycosim("report", str(run)).stdout
    assert "iteration: up to 50 takes of each step" in text and "takes per step: mean" in text
    assert list(read_steps(run)["takes"]) == takes[1:]
    _plots_panels(run, tmp_path / "i.png", ["a.y"], 2)  # the values, and the takes under them


def test_relaxation_makes_a_loop_converge_and_a_step_that_does_not_is_reported_or_ends_the_run(tmp_path):
    """a = −1.5·b + 1, b = 1.5·a: the plain fixed point spirals out (gain 1.5 round the loop);
    damped by 0.3 it converges to a = 1/3.25."""
    cosim = {"iterate": {"tolerance": 1e-9, "maxIterations": 4}}
    run = run_project(_loop(tmp_path, -1.5, 1.5, **cosim), tmp_path / "go")
    m = meta(run)
    steps = len(read_rows(run)) - 1
    assert m["iterations"]["not_converged"] == steps and _takes(run)[1:] == [4] * steps
    assert m["iterations"]["worst"]["port"] in ("a.u", "b.u")
    assert f"{steps} steps did not converge; worst: input" in hycosim("report", str(run)).stdout

    cosim["iterate"]["onFailure"] = "stop"
    res = hycosim("run", str(_loop(tmp_path, -1.5, 1.5, **cosim)), "--runs-dir", str(tmp_path / "stop"), "--no-progress")
    assert res.returncode != 0 and "step 0 (t=0 s) did not converge in 4 takes: input" in res.stderr, res.stderr
    assert "Traceback" not in res.stderr

    cosim = {"iterate": {"tolerance": 1e-9, "maxIterations": 200, "relaxation": 0.3}}
    rows = read_rows(run_project(_loop(tmp_path, -1.5, 1.5, **cosim), tmp_path / "damped"))
    assert column(rows, "a.y")[-1] == pytest.approx(1 / 3.25, rel=1e-6)
    assert column(rows, "b.y")[-1] == pytest.approx(1.5 / 3.25, rel=1e-6)


def _ball(tmp_path: Path, **cosim) -> Path:
    return write_project(tmp_path / "ball.json", [
        {"nodeName": "ball", "UID": 1, "model": "bouncing_ball", "output": ["h", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "ball.v", "to": "g.u"}], cosim={"stepSize": 0.01, "stopTime": 1.5, **cosim})


def test_the_error_controlled_step_is_short_where_the_inputs_move_fast_and_long_where_they_do_not(tmp_path):
    # The held input's error over a step is |Δu|·h/2. Free fall: Δv = 9.81·h, so steps of some
    # 0.02–0.04 s; a bounce: Δv ≈ 2|v| at once, so steps of a few ms.
    tol = 0.002
    run = run_project(_ball(tmp_path, stepControl={"tolerance": tol, "minStep": 1e-4, "maxStep": 0.2}),
                      tmp_path / "runs")
    rows = read_rows(run)
    t, u = column(rows, "t"), column(rows, "g.u")
    h = [b - a for a, b in zip(t, t[1:])]
    assert t[-1] == 1.5 and all(x > 0 for x in h)
    sizes = meta(run)["step_sizes"]
    assert sizes["rejected"] > 0 and sizes["accepted"] == len(h)
    assert min(h[:-1]) < 0.003 and max(h) > 0.02  # shrunk at the bounce, grown in free fall
    # Every step that stood held its input within the tolerance, unless taken at minStep.
    v = column(rows, "ball.v")
    for k in range(len(h)):
        if h[k] > 1.0001e-4:
            assert abs(v[k + 1] - u[k]) * h[k] / 2 <= tol * max(1.0, abs(u[k]), abs(v[k + 1])) + 1e-12, k
    text = hycosim("report", str(run)).stdout
    assert "step control: steps of 0.0001 to 0.2 s" in text and "macro steps used:" in text
    assert list(read_steps(run)["h"]) == pytest.approx(h)
    _plots_panels(run, tmp_path / "h.png", ["ball.h"], 3)  # the values, the step lengths, the takes


def _plots_panels(run: Path, png: Path, ports: list[str], panels: int) -> None:
    """``hycosim plot`` draws the run with ``panels`` rows of plots (the figure's height grows by row)."""
    import matplotlib.image

    res = hycosim("plot", str(run), *ports, "-o", str(png))
    assert res.returncode == 0, res.stderr
    height, width = matplotlib.image.imread(png).shape[:2]
    assert width == 1100 and height == 110 * (5 + 2 * (panels - 1))


def test_retakes_refuse_what_cannot_take_a_step_again_by_name(tmp_path):
    (tmp_path / "hold.py").write_text(
        "from hycosim.node.interface import Node\n"
        "class Hold(Node):\n"
        "    def outputs(self):\n        return {'y': 0.0}\n"
        "    def step(self, t, h, inputs):\n        pass\n")
    nodes = [{"nodeName": "src", "UID": 1, "model": "ramp", "output": ["y", "v"]},
             {"nodeName": "h", "UID": 2, "model": "hold.py:Hold", "input": ["u"], "output": ["y"]}]
    for key, value in (("iterate", {"tolerance": 1e-6}),
                       ("stepControl", {"tolerance": 1e-3, "minStep": 1e-3, "maxStep": 0.1})):
        cfg = write_project(tmp_path / "p.json", nodes, [{"from": "src.y", "to": "h.u"}], cosim={key: value})
        res = hycosim("validate", str(cfg))
        assert res.returncode == 2, res.stdout
        assert f"coSimulation.{key}: every stepping node must be able to take a step again" in res.stderr
        assert "node 'h': its model Hold has no get_state or set_state" in res.stderr and "Traceback" not in res.stderr


_SAVED = """
from hycosim.node.interface import Node, pack_state, unpack_state

class Saved(Node):  # saves its state and says nothing of can_rollback: the default follows the methods
    def setup(self, ctx):
        self.x = 0.0
    def outputs(self):
        return {"y": self.x}
    def step(self, t, h, inputs):
        self.x += h * inputs["u"]
    def get_state(self):
        return pack_state({"x": self.x})
{set_state}
"""


def test_a_python_node_that_saves_its_state_is_retried_and_checkpointed_without_saying_can_rollback(tmp_path):
    """A model with get_state and set_state (and no can_rollback of its own) takes part in
    iterative coupling and in checkpoints; one with get_state alone is named by validate."""
    (tmp_path / "saved.py").write_text(_SAVED.replace("{set_state}", (
        "    def set_state(self, state):\n        self.x = unpack_state(state, {'x'})['x']\n")))
    (tmp_path / "half.py").write_text(_SAVED.replace("{set_state}", "").replace("class Saved", "class Half"))
    nodes = [{"nodeName": "src", "UID": 1, "model": "ramp", "output": ["y", "v"]},
             {"nodeName": "s", "UID": 2, "model": "saved.py:Saved", "input": ["u"], "output": ["y"]}]
    cfg = write_project(tmp_path / "p.json", nodes, [{"from": "src.y", "to": "s.u"}],
                        cosim={"stopTime": 0.5, "iterate": {"tolerance": 1e-9}, "checkpointEvery": 0.1})
    res = hycosim("validate", str(cfg))
    assert res.returncode == 0 and "checkpoints" not in res.stderr, res.stderr
    m = meta(run_project(cfg, tmp_path / "runs"))
    assert m["checkpoints_taken"] >= 4 and m["iteration"].startswith("up to"), m
    nodes[1]["model"] = "half.py:Half"
    cfg = write_project(tmp_path / "h.json", nodes, [{"from": "src.y", "to": "s.u"}],
                        cosim={"stopTime": 0.5, "iterate": {"tolerance": 1e-9}})
    res = hycosim("validate", str(cfg))
    assert res.returncode == 2 and "node 's': its model Half has no set_state" in res.stderr


def test_validate_lists_what_each_node_takes_part_in_and_warns_where_the_project_asks_more(tmp_path):
    """Issue 59, part 2: per stepping node, checkpoints / iteration / localisation /
    interpolation; a warning names each node that cannot give what the project asks for."""
    (tmp_path / "saved.py").write_text(_SAVED.replace("{set_state}", (
        "    def set_state(self, state):\n        self.x = unpack_state(state, {'x'})['x']\n")))
    (tmp_path / "half.py").write_text(_SAVED.replace("{set_state}", "").replace("class Saved", "class Half"))
    nodes = [{"nodeName": "src", "UID": 1, "model": "ramp", "output": ["y", "v"]},
             {"nodeName": "s", "UID": 2, "model": "saved.py:Saved", "input": ["u"], "output": ["y"]},
             {"nodeName": "half", "UID": 3, "model": "half.py:Half", "input": ["u"], "output": ["y"]}]
    links = [{"from": "src.y", "to": "s.u"}, {"from": "src.y", "to": "half.u"}]
    events = [{"name": "e", "when": "src.y > 0.2", "drives": "s", "until": "src.y > 0.4"}]
    cfg = write_project(tmp_path / "p.json", nodes, links, events=events,
                        cosim={"stopTime": 0.5, "checkpointEvery": 0.1, "eventTolerance": 1e-4})
    res = hycosim("validate", str(cfg))
    assert res.returncode == 0, res.stderr
    rows = {cells[0]: cells[1:] for line in res.stdout.splitlines()
            if len(cells := [c.strip() for c in re.split("[│┃]", line.strip("│┃ \n"))]) == 5}
    assert rows["node"] == ["checkpoints", "iteration", "localisation", "interpolation"]
    assert rows["s"] == ["yes", "yes", "yes", "no: its model Saved has no set_input_derivatives"]
    assert rows["half"][:3] == ["no: its model Half has no set_state"] * 3
    assert rows["src"][3] == "no: it has no inputs"
    assert ("coSimulation.checkpointEvery: node 'half' cannot take part in checkpoints: its model Half has no "
            "set_state") in res.stderr
    assert "coSimulation.eventTolerance: node 'half' cannot take a step again with another length" in res.stderr
    assert "node 's'" not in res.stderr and "node 'src'" not in res.stderr


@pytest.mark.parametrize("cosim, expected", [
    ({"iterate": {"tolerance": 0}}, "coSimulation.iterate.tolerance"),
    ({"iterate": {"tolerance": 1e-6, "relaxation": 1.5}}, "coSimulation.iterate.relaxation"),
    ({"iterate": {"tolerance": 1e-6, "maxIterations": 1}}, "coSimulation.iterate.maxIterations"),
    ({"iterate": {"tolerance": 1e-6, "interpolate": 4}}, "coSimulation.iterate.interpolate"),
    ({"iterate": {"tolerance": 1e-6, "interpolate": -1}}, "coSimulation.iterate.interpolate"),
    ({"stepControl": {"tolerance": -1, "minStep": 0.001, "maxStep": 0.1}}, "coSimulation.stepControl.tolerance"),
    ({"stepControl": {"tolerance": 1e-3, "minStep": 0.2, "maxStep": 0.1}},
     "coSimulation.stepControl: minStep 0.2 s is above maxStep 0.1 s"),
    ({"stepControl": {"tolerance": 1e-3, "minStep": 0.001, "maxStep": 0.1}, "iterate": {"tolerance": 1e-6}},
     "iterative coupling and an error-controlled step cannot be combined"),
    ({"iterate": {"tolerance": 1e-6}, "coupling": "gauss-seidel"},
     "coSimulation.iterate: iterative coupling works with Jacobi coupling only"),
    ({"stepControl": {"tolerance": 1e-3, "minStep": 0.001, "maxStep": 0.1}, "eventTolerance": 0.001},
     "coSimulation.stepControl: an error-controlled step and locating events by rollback cannot be combined"),
])
def test_bad_retake_settings_are_named(cosim, expected):
    doc = {"nodeNum": 2, "nodeLists": [
        {"nodeName": "a", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "b", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]}],
        "linkNum": 1, "linkLists": [{"from": "a.y", "to": "b.u"}], "coSimulation": {"stepSize": 0.01, **cosim}}
    with pytest.raises(Exception) as info:
        parse_project(json.loads(json.dumps(doc)), "p.json")
    assert expected in str(info.value)


def test_algebraic_loops_follow_feedthrough_inside_nodes_only():
    doc = {"nodeNum": 3, "nodeLists": [
        {"nodeName": n, "UID": i, "model": "gain", "input": ["u"], "output": ["y"]} for i, n in enumerate("abc", 1)],
        "linkNum": 3, "linkLists": [{"from": "a.y", "to": "b.u"}, {"from": "b.y", "to": "c.u"},
                                    {"from": "c.y", "to": "a.u"}]}
    routes = parse_project(doc).routes
    through = {n: {"y": {"u"}} for n in "abc"}
    assert algebraic_loops(routes, through) == [["a.u", "a.y", "b.u", "b.y", "c.u", "c.y", "a.u"]]
    assert algebraic_loops(routes, {**through, "b": {}}) == []  # b's output is its state: no loop


def test_the_step_size_control_and_the_change_it_reads():
    from hycosim.core.schema import StepControl

    labels = {"n": ["n.x", "n.F", "n.flag"]}
    change, port, absolute = input_change({"n": [0.1, 50.0, True]}, {"n": [0.0, 40.0, False]}, labels, 0.1)
    assert port == "n.F" and absolute == 10.0 and change == pytest.approx(10.0 / (0.1 * 50.0))
    sizer = StepSizer.starting(StepControl(tolerance=0.1, minStep=0.001, maxStep=0.1), 0.5)
    assert sizer.h == 0.1  # the first step tried lies within the bounds
    # Judged: the held input's error over the step, change·h/2 tolerances; it grows as h².
    assert sizer.judge(0.1, 19.0) is None and sizer.rejected == 0  # 0.95: within the tolerance
    assert sizer.judge(0.1, 40.0) == pytest.approx(0.1 * (0.8 / 2.0) ** 0.5) and sizer.rejected == 1
    shorter = sizer.judge(0.1, 1000.0)
    assert shorter == pytest.approx(0.1 * 0.2) and sizer.rejected == 2  # at most five times shorter at once
    assert sizer.judge(0.02, 50.0) is None and sizer.h == pytest.approx(0.02 * 1.6 ** 0.5)
    assert sizer.judge(0.02, 0.5) is None and sizer.h == pytest.approx(0.04)  # at most twice as long
    assert sizer.judge(0.001, 9000.0) is None and sizer.forced == 1  # minStep stands over the tolerance


def _two_masses(tmp_path: Path, fmu: Path, h: float, degree: int, extra: list[dict] | None = None, **cosim) -> Path:
    """benchmarks/accuracy.py's two-mass oscillator on its native mass FMU: m1 gives its
    displacement, m2 holds the coupling spring (100 N/m) and gives back its force."""
    masses = [
        {"nodeName": "m1", "UID": 1, "fmu": str(fmu), "input": ["F"], "output": ["x", "v"], "parameters": {"x": 0.1}},
        {"nodeName": "m2", "UID": 2, "fmu": str(fmu), "input": ["xl"], "output": ["x", "v", "Fl"],
         "parameters": {"kl": 100.0, "xl": 0.1}},
    ]
    links = [{"from": "m1.x", "to": "m2.xl"}, {"from": "m2.Fl", "to": "m1.F"}]
    for i, node in enumerate(extra or []):
        masses.append(node)
        links.append({"from": "m1.x", "to": f"{node['nodeName']}.u"})
    cosim = {"stepSize": h, "stopTime": 0.4,
             "iterate": {"tolerance": 1e-11, "maxIterations": 30, "interpolate": degree}, **cosim}
    return write_project(tmp_path / f"osc-{degree}-{h:g}.json", masses, links, cosim=cosim)


def _exact_x1(t: list[float]) -> list[float]:
    """x1 of the two-mass system (m = 1 kg, k = 10 N/m to the walls, 100 N/m between) from x1 = 0.1 m."""
    import numpy as np

    a = np.array([[0, 1, 0, 0], [-110, 0, 100, 0], [0, 0, 0, 1], [100, 0, -110, 0]], dtype=float)
    w, v = np.linalg.eig(a)
    c = np.linalg.solve(v, np.array([0.1, 0, 0, 0], dtype=complex))
    return [float(np.real(v[0] @ (c * np.exp(w * s)))) for s in t]


def test_inputs_interpolated_over_the_step_raise_the_order_of_iterative_coupling_to_the_polynomials(tmp_path):
    """Held at the end value the coupled inputs make iterative coupling first order; following
    a line over the step (FMI input derivatives) second, a cubic fourth, as RK4 on the whole
    system is. Measured on two native FMUs, the error halving H."""
    from benchmarks._mass_fmu import build

    fmu = build(tmp_path / "fmu")
    errors: dict[int, list[float]] = {}
    for degree in (0, 1, 3):
        for h in (0.02, 0.01):
            rows = read_rows(run_project(_two_masses(tmp_path, fmu, h, degree), tmp_path / f"r{degree}-{h:g}"))
            t, x1 = column(rows, "t"), column(rows, "m1.x")
            errors.setdefault(degree, []).append(max(abs(a - b) for a, b in zip(x1, _exact_x1(t))))
    order = {d: math.log2(e[0] / e[1]) for d, e in errors.items()}
    assert 0.6 < order[0] < 1.4 and 1.7 < order[1] < 2.3 and order[3] > 3.5, (order, errors)
    assert errors[3][1] < errors[1][1] / 20 < errors[0][1] / 200


def test_a_node_that_cannot_interpolate_holds_the_end_value_and_the_start_up_steps_are_short(tmp_path):
    from benchmarks._mass_fmu import build

    fmu = build(tmp_path / "fmu")
    probe = {"nodeName": "probe", "UID": 3, "model": "gain", "parameters": {"k": 1.0}, "input": ["u"], "output": ["y"]}
    cfg = _two_masses(tmp_path, fmu, 0.02, 3, [probe])
    res = hycosim("validate", str(cfg))
    assert res.returncode == 0 and "'m1'" not in res.stderr and "'m2'" not in res.stderr
    assert ("coSimulation.iterate.interpolate: node 'probe' holds its inputs at the step's end value: its model "
            "Gain has no set_input_derivatives") in " ".join(res.stderr.split())
    run = run_project(cfg, tmp_path / "r")
    said = meta(run)["iteration"]
    assert "inputs of m1, m2 interpolated over each step by polynomials of degree 3" in said
    assert "probe cannot interpolate its inputs and holds the step's end value" in said
    rows = read_rows(run)
    t = column(rows, "t")
    # Two macro steps of 20 ms as 8 of 2.5 ms each, then 20 ms on: 16 + 18 steps to 0.4 s.
    assert t[:3] == pytest.approx([0.0, 0.0025, 0.005]) and t[16] == pytest.approx(0.04)
    assert t[17] == pytest.approx(0.06) and len(t) == 16 + 18 + 1 and t[-1] == pytest.approx(0.4)
    # Recorded at each point: what each node had there, m1's x at m2.xl (m2 interpolates), and
    # for the probe the end value its step was taken on: m1's x at the next point.
    x1, xl, u = column(rows, "m1.x"), column(rows, "m2.xl"), column(rows, "probe.u")
    assert all(a == pytest.approx(b, abs=1e-12) for a, b in zip(x1, xl))
    assert all(a == pytest.approx(b, abs=1e-9) for a, b in zip(x1[1:-1], u[:-2]))


@pytest.mark.parametrize("victim", ["node m2", "server"])
def test_a_process_killed_under_interpolated_inputs_is_recovered_to_what_the_run_records_unkilled(tmp_path, victim):
    """The points the polynomials go through are in the checkpoint: after m2 is killed, or the
    server and the run is resumed, the steps from the checkpoint are taken on the same
    polynomials as before."""
    from benchmarks._mass_fmu import build
    from tests.helpers import run_killing

    fmu = build(tmp_path / "fmu")
    slow = {"nodeName": "probe", "UID": 3, "model": "gain", "parameters": {"k": 1.0, "work_s": 0.002},
            "input": ["u"], "output": ["y"]}

    def project(where: Path) -> Path:
        where.mkdir()
        return _two_masses(where, fmu, 0.01, 3, [slow], stopTime=2.0, checkpointEvery=0.3, attachTimeout=20.0)

    reference = (run_project(project(tmp_path / "ref"), tmp_path / "ref-runs", timeout=240) / "values.csv").read_bytes()
    cfg = project(tmp_path / "killed")
    code, err = run_killing(cfg, tmp_path / "runs", [(victim, 100)])
    run = next((tmp_path / "runs").iterdir())
    if victim == "server":
        assert code == 3 and "--resume" in err
        res = hycosim("run", str(cfg), "--resume", str(run), "--no-progress", timeout=120)
        code, err = res.returncode, res.stderr
    assert code == 0, err
    assert [r["node"] for r in meta(run)["recoveries"]] == [victim.split()[-1]]
    assert (run / "values.csv").read_bytes() == reference
