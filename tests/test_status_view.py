"""The status answer's view of the latest points: the barrier's last second from samples of it,
and the points after a step, thinned, checked against reckoning every point."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hycosim.master.status_view import STATUS_POINTS, WINDOW_SAMPLES, barrier_window, points_since

NODES = ["a", "b", "c"]


@st.composite
def recents(draw, most: int = 600):
    """Points in time order: gaps from 0 to 20 ms, random holders, waits and arrivals, and
    between any two up to 3 points told and not kept."""
    gaps = draw(st.lists(st.floats(0.0, 0.02), min_size=0, max_size=most))
    t, told, points = 100.0, 0, []
    for gap in gaps:
        t, told = t + gap, told + 1 + draw(st.integers(0, 3))
        arrivals = draw(st.dictionaries(st.sampled_from(NODES), st.floats(0.0, 0.01), max_size=3))
        points.append((t, draw(st.sampled_from(["", *NODES])), draw(st.floats(0.0, 0.01)), arrivals, told))
    return points, t + draw(st.floats(0.0, 0.5))


def _every_point(recent, now):
    """The window as reckoned from every point of the second (what the server did before)."""
    second = [p for p in recent if p[0] >= now - 1.0]
    held, arrived = {}, {}
    for _, holder, wait, arrivals, _ in second:
        if holder:
            held[holder] = held.get(holder, 0.0) + wait
        for node, at in arrivals.items():
            arrived.setdefault(node, []).append(at)
    return second, held, arrived


@given(recents())
def test_window_counts_the_second_and_samples_within_it(drawn):
    recent, now = drawn
    window = barrier_window(recent, now, kept=10_000)
    second, held, arrived = _every_point(recent, now)
    # Every point told from the second's first kept one to its last, kept or not.
    assert window["steps"] == (second[-1][4] - second[0][4] + 1 if second else 0) >= len(second)
    assert set(window["held"]) <= set(held) and set(window["arrival_ms"]) <= set(arrived)
    if window["held"]:
        assert math.isclose(sum(window["held"].values()), 1.0)
    for node, mean in window["arrival_ms"].items():  # a mean of samples lies within all of them
        assert 1000 * min(arrived[node]) - 1e-9 <= mean <= 1000 * max(arrived[node]) + 1e-9
    if len(second) <= WINDOW_SAMPLES:  # few enough points: every one is reckoned
        total = sum(held.values())
        assert window["held"] == ({n: w / total for n, w in held.items()} if total > 0 else {})
        assert window["arrival_ms"] == pytest.approx({n: 1000 * sum(a) / len(a) for n, a in arrived.items()})


@pytest.mark.parametrize("period", [2, 3, 12, 24, 64])
def test_window_samples_a_busy_second_without_aliasing(period):
    # 3,000 points in the second, node a held the barrier on every period-th: its share is
    # 1/period whatever the period (every k-th point would see a alone, or never).
    now = 10.0
    recent = [(now - 1.0 + (i + 0.5) / 3000, "a" if i % period == 0 else "b", 1e-3, {"a": 2e-3, "b": 1e-3}, i + 1)
              for i in range(3000)]
    window = barrier_window(recent, now, kept=4096)
    assert window["steps"] == 3000
    assert abs(window["held"]["a"] - 1 / period) < 0.1
    assert window["arrival_ms"] == {"a": pytest.approx(2.0), "b": pytest.approx(1.0)}


def test_window_reckons_the_rate_when_the_kept_points_span_less_than_a_second():
    # 4,096 points kept at 10,000 steps/s span 0.41 s: the steps of a second are their rate.
    now = 50.0
    recent = [(now - (4095 - i) / 10_000, "a", 1e-4, {}, i + 1) for i in range(4096)]
    assert barrier_window(recent, now, kept=4096)["steps"] == 10_000
    assert barrier_window(recent, now, kept=8192)["steps"] == 4096  # not full: all there were


@st.composite
def histories(draw):
    """Kept points (step, t, mode, outputs, inputs, wall); steps rise, or go back once (a restore)."""
    steps = list(range(draw(st.integers(0, 2000))))
    back = draw(st.integers(0, len(steps)))
    steps += list(range(back, back + draw(st.integers(0, 300))))
    return [(k, 0.01 * k, "free", {"a": [float(k)]}, {"b": [float(-k)]}, None) for k in steps]


@given(histories(), st.integers(-5, 2500))
def test_points_since_are_after_the_step_thinned_with_the_latest(history, since):
    points = points_since(history, since)
    after = [p for p in history if p[0] > since]
    assert len(points) <= STATUS_POINTS
    assert all(k > since for k, *_ in points)
    if after:
        assert points[-1] == [after[-1][0], after[-1][1], after[-1][3], after[-1][4]]
    if len(after) <= STATUS_POINTS:
        assert points == [[k, t, o, i] for k, t, _, o, i, _ in after]
    else:  # evenly thinned: no gap between those sent is much wider than the rest
        index = {id(p[3]): j for j, p in enumerate(after)}
        at = [index[id(p[2])] for p in points]
        stride = -(-len(after) // STATUS_POINTS)
        assert {b - a for a, b in zip(at, at[1:])} == {stride}
        assert len(points) == -(-len(after) // stride)


@given(gaps=st.lists(st.floats(0.0, 0.2), max_size=300), per_s=st.floats(1.0, 100.0), burst=st.integers(1, 30))
def test_the_answer_budget_grants_at_most_its_rate_and_burst_and_refuses_only_beyond_them(gaps, per_s, burst):
    """Questions at any times: the answers granted by any moment are at most the burst plus the
    rate times the time gone by, every refusal is counted, and a question that finds the
    bucket refilled for one more is never refused."""
    from hycosim.transport.answer_budget import AnswerBudget

    now = [0.0]
    budget = AnswerBudget(per_s, burst, clock=lambda: now[0])
    granted = 0
    tokens = float(burst)  # reckoned here alongside, as the bucket should
    for gap in gaps:
        now[0] += gap
        tokens = min(float(burst), tokens + gap * per_s)
        took = budget.take()
        if abs(tokens - 1.0) > 1e-6:  # (at the edge, rounding decides)
            assert took == (tokens > 1.0)
        if took:
            granted, tokens = granted + 1, max(0.0, tokens - 1.0)
        assert granted <= burst + per_s * now[0] + 1e-6
    assert budget.refused == len(gaps) - granted


def test_an_asker_within_the_budget_is_never_refused():
    from hycosim.transport.answer_budget import AnswerBudget

    now = [0.0]
    budget = AnswerBudget(32.0, 20, clock=lambda: now[0])
    for _ in range(2000):  # askers at the budget's rate (times a power of two: no rounding in the sums)
        now[0] += 1 / 32
        assert budget.take()
    assert budget.refused == 0
    # then a loop at once: what is left of the burst (one went to the last steady question), no more
    assert sum(budget.take() for _ in range(100)) == 19 and budget.refused == 81


def _point(project, released):
    from hycosim.master.observers import RecordedPoint

    point = RecordedPoint(project)
    point.mode, point.outputs, point.inputs = "free", {"a": [released or 0.0], "b": [2.0]}, {"a": [], "b": [3.0]}
    point.released, point.holder, point.wait_s, point.arrivals = released, "a", 0.001, {"a": 0.001}
    return point


def test_the_status_answer_follows_the_points_as_an_observer_and_a_rollback():
    from hycosim.core.schema import Project
    from hycosim.master.status_view import LatestPoints

    project = Project.model_validate({
        "projectName": "p", "nodeNum": 2, "linkNum": 1,
        "nodeLists": [{"nodeName": "a", "UID": 1, "model": "ramp", "output": ["y"]},
                      {"nodeName": "b", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]}],
        "linkLists": [{"from": "a.y", "to": "b.u"}], "coSimulation": {"stepSize": 0.1, "stopTime": 1.0}})
    latest = LatestPoints(project, 100)
    assert latest.answer(0.0, since=-1)["outputs"] == {}  # no point yet
    for k in range(8):
        # Points 3 and 4 lie inside a batched release: no release of their own.
        latest.step_complete(k, 0.1 * k, _point(project, None if k in (3, 4) else float(k)))
    assert [step for step, *_ in latest.history] == list(range(8)) and len(latest.recent) == 6
    latest.state_restored(5, 0.5)
    answer = latest.answer(8.0, since=-1)
    assert [p[0] for p in answer["points"]] == [0, 1, 2, 3, 4] and answer["step"] == 7
    latest.step_complete(5, 0.5, _point(project, 9.0))
    assert latest.answer(9.5, since=4)["points"][0][0] == 5


@st.composite
def projects_and_points(draw):
    """A project of 1 to 5 nodes, each with 0 to 3 inputs and outputs (some arrays), and points
    whose values are any of their ports' kinds, as the master gives them (every node, ports in order)."""
    from hycosim.core.schema import Project

    nodes, ports = [], {}
    for i in range(draw(st.integers(1, 5))):
        name = f"n{i}"
        shapes = {side: draw(st.lists(st.sampled_from([None, [2], [2, 2]]), max_size=3)) for side in ("input", "output")}
        ports[name] = shapes
        nodes.append({"nodeName": name, "UID": i + 1, "model": "gain",
                      **{side: [{"name": f"{side[0]}{j}", **({"shape": s} if s else {})} for j, s in enumerate(shapes[side])]
                         for side in ("input", "output")}})
    project = Project.model_validate({"projectName": "p", "nodeNum": len(nodes), "linkNum": 0, "nodeLists": nodes,
                                      "linkLists": [], "coSimulation": {"stepSize": 0.1, "stopTime": 1.0}})
    number = st.floats(allow_nan=False) | st.integers(-2**70, 2**70) | st.booleans()

    def value(shape):
        if shape is None:
            return draw(number)
        return draw(st.lists(number, min_size=math.prod(shape), max_size=math.prod(shape)))

    points = [({n: [value(s) for s in ports[n]["output"]] for n in ports},
               {n: [value(s) for s in ports[n]["input"]] for n in ports}) for _ in range(draw(st.integers(1, 5)))]
    return project, points


@given(projects_and_points())
def test_the_status_answer_gives_each_point_as_it_was_told(case):
    """The values kept flat come back as the mappings they were: the latest point's, and each
    point's in the list after a step, however many nodes and ports, arrays among them."""
    from hycosim.master.observers import RecordedPoint
    from hycosim.master.status_view import LatestPoints

    project, points = case
    latest = LatestPoints(project, 100)
    point = RecordedPoint(project)
    point.stepped, point.lateness_s, point.takes = None, None, 1
    for k, (outputs, inputs) in enumerate(points):
        point.mode, point.outputs, point.inputs = "free", outputs, inputs
        point.released, point.holder, point.wait_s, point.arrivals, point.ages = float(k), "n0", 0.0, {}, {}
        latest.step_complete(k, 0.1 * k, point)
        # The loop changes its lists after the call: what was kept must not change with them.
        for values in (*outputs.values(), *inputs.values()):
            values.append("changed")
    answer = latest.answer(10.0, since=-1)
    expected = [({n: v[:-1] for n, v in o.items()}, {n: v[:-1] for n, v in i.items()}) for o, i in points]
    assert (answer["outputs"], answer["inputs"]) == expected[-1]
    assert [(o, i) for _, _, o, i in answer["points"]] == expected


def test_the_status_answer_takes_a_point_a_millisecond_counts_them_all_and_keeps_the_last():
    """Points told ten a millisecond are taken one a millisecond, the steps a second counted
    from all of them; the last told, not taken, becomes the answer's at the run's end, unless a
    rollback went back before it."""
    from hycosim.core.schema import Project
    from hycosim.master.status_view import LatestPoints

    project = Project.model_validate({
        "projectName": "p", "nodeNum": 2, "linkNum": 1,
        "nodeLists": [{"nodeName": "a", "UID": 1, "model": "ramp", "output": ["y"]},
                      {"nodeName": "b", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]}],
        "linkLists": [{"from": "a.y", "to": "b.u"}], "coSimulation": {"stepSize": 0.1, "stopTime": 1.0}})
    latest = LatestPoints(project, 4096, every_s=0.001)
    for k in range(1005):  # 0.1 ms apart: 100.5 ms of points
        latest.step_complete(k, 0.1 * k, _point(project, 10.0 + 1e-4 * k))
    taken = [step for step, *_ in latest.history]
    # One point of each millisecond (floating point may move a boundary by one point).
    assert taken[0] == 0 and 100 <= len(taken) <= 101 and all(9 <= b - a <= 11 for a, b in zip(taken, taken[1:]))
    answer = latest.answer(10.5, since=None)
    assert answer["window"]["steps"] == taken[-1] + 1  # from the first kept to the last, all counted
    assert answer["step"] == taken[-1] < 1004
    latest.run_ended("completed")
    answer = latest.answer(10.5, since=taken[-2])
    assert answer["step"] == 1004 and answer["outputs"] == {"a": [10.0 + 1e-4 * 1004], "b": [2.0]}
    assert [p[0] for p in answer["points"]] == [taken[-1], 1004]
    assert answer["window"]["steps"] == 1005  # every point told, counted once

    # A point left untaken, then a rollback to before it: the run's end takes nothing back.
    again = LatestPoints(project, 4096, every_s=0.001)
    for k in range(3):
        again.step_complete(k, 0.1 * k, _point(project, 20.0 + 1e-4 * k))
    again.state_restored(1, 0.1)
    again.run_ended("completed")
    assert again.answer(20.5, since=None)["step"] == 0 and [s for s, *_ in again.history] == [0]
