"""The hybrid coordinator: a guard fires, the driven node follows its driver, release resumes free dynamics."""

from __future__ import annotations

import json
import math

from tests.helpers import column, hycosim, meta, read_rows, run_project, write_project

G = 9.81
H = 0.01


def _ball_and_hand(tmp_path, when: str, until: str):
    """A ball falling from 2 m and a hand rising as 0.5 + 0.2 t; in mode catch the ball follows the hand."""
    return write_project(tmp_path / "p.json", [
        {"nodeName": "ball", "UID": 1, "model": "bouncing_ball", "parameters": {"h0": 2.0, "v0": 0.0, "g": G, "e": 0.8},
         "input": ["h_in", "v_in"], "output": ["h", "v", {"name": "impacts", "type": "Integer"}]},
        {"nodeName": "hand", "UID": 2, "model": "ramp", "parameters": {"a": 0.2, "b": 0.5}, "output": ["y", "v"]},
    ], [{"from": "hand", "to": "ball", "pairs": [["y", "h_in"], ["v", "v_in"]], "activeIn": ["catch"]}],
        events=[{"name": "catch", "when": when, "drives": "ball", "until": until}],
        cosim={"stepSize": H, "stopTime": 2.4})


def test_catch_and_release_of_a_falling_ball(tmp_path):
    cfg = _ball_and_hand(tmp_path, "ball.h <= hand.y and hand.y < 1.0", "hand.y >= 1.2")
    run = run_project(cfg, tmp_path / "runs")
    rows = read_rows(run)
    t = column(rows, "t")
    h, v, hand = column(rows, "ball.h"), column(rows, "ball.v"), column(rows, "hand.y")
    modes = [r["mode"] for r in rows]

    # Free fall until the guard holds at a macro-step point (Eq. 1–3).
    k_catch = next(k for k in range(len(rows)) if h[k] <= hand[k])
    for k in range(k_catch + 1):
        assert math.isclose(h[k], 2.0 - G * t[k] ** 2 / 2, abs_tol=1e-9)
        assert modes[k] == ("catch" if k == k_catch else "free")
    assert math.isclose(t[k_catch], math.ceil((-0.5 + math.sqrt(0.25 + 4 * 4.905 * 1.8)) / (2 * 4.905) / H) * H, abs_tol=1e-9)

    # Driven: s_A = g_B(s_B), one macro step behind the driver (Eq. 4).
    k_release = next(k for k in range(k_catch + 1, len(rows)) if hand[k] >= 1.2)
    for k in range(k_catch + 1, k_release + 1):
        assert h[k] == hand[k - 1]
        assert v[k] == 0.5
        assert modes[k] == ("free" if k == k_release else "catch")

    # Released: free flight from where the hand left it (Eq. 5), up to the next impact.
    h_rel, v_rel = h[k_release], v[k_release]
    for k in range(k_release + 1, len(rows)):
        tau = t[k] - t[k_release]
        expected = h_rel + v_rel * tau - G * tau ** 2 / 2
        if expected <= 0:
            break
        assert math.isclose(h[k], expected, abs_tol=1e-9)
        assert modes[k] == "free"

    events = [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]
    assert [(e["step"], e["from"], e["to"]) for e in events] == [(k_catch, "free", "catch"), (k_release, "catch", "free")]
    assert events[0]["values"] == {"ball.h": h[k_catch], "hand.y": hand[k_catch]}
    assert events[1]["values"] == {"hand.y": hand[k_release]}
    assert math.isclose(events[0]["t"], t[k_catch])


def _coordinator(*events: dict):
    from hycosim.core.schema import Event
    from hycosim.core.config import EventGuards
    from hycosim.core.guards import Guard
    from hycosim.master.coordinator import Coordinator

    parsed = [Event(**e) for e in events]
    return Coordinator(parsed, {e.name: EventGuards(Guard(e.when), Guard(e.until), Guard(e.rearm) if e.rearm else None)
                                for e in parsed})


def _modes(coordinator, points: list[dict[str, float]]) -> list[str]:
    modes = []
    for k, point in enumerate(points):
        coordinator.update(k, 0.1 * k, {tuple(name.split(".")): v for name, v in point.items()})
        modes.append(coordinator.mode)
    return modes


def test_a_when_still_holding_at_its_release_waits_for_its_edge():
    c = _coordinator({"name": "grip", "when": "r.near > 0.5", "drives": "r", "until": "r.open > 0.5"})
    points = [{"r.near": 0, "r.open": 0}, {"r.near": 1, "r.open": 0}, {"r.near": 1, "r.open": 1},
              {"r.near": 1, "r.open": 1}, {"r.near": 1, "r.open": 0}, {"r.near": 0, "r.open": 0},
              {"r.near": 1, "r.open": 0}]
    # Level-triggered, points 3 and 4 would switch straight back to grip.
    assert _modes(c, points) == ["free", "grip", "free", "free", "free", "free", "grip"]


def test_a_rearm_guard_gives_hysteresis():
    c = _coordinator({"name": "low", "when": "x.v < 1.0", "drives": "x", "until": "x.v >= 1.0", "rearm": "x.v > 1.2"})
    values = [1.1, 0.9, 1.05, 0.95, 1.1, 0.99, 1.3, 0.9]
    assert _modes(c, [{"x.v": v} for v in values]) == ["free", "low", "free", "free", "free", "free", "free", "low"]


def test_an_edge_passing_while_another_event_is_active_rearms():
    c = _coordinator({"name": "a", "when": "n.a > 0.5", "drives": "n", "until": "n.a_off > 0.5"},
                     {"name": "b", "when": "n.b > 0.5", "drives": "n", "until": "n.b_off > 0.5"})
    p = lambda a, a_off, b, b_off: {"n.a": a, "n.a_off": a_off, "n.b": b, "n.b_off": b_off}
    points = [p(1, 0, 0, 0), p(1, 1, 1, 0), p(1, 0, 1, 0), p(0, 0, 1, 0), p(1, 0, 0, 1), p(1, 0, 0, 0)]
    # a released at 1; b fires at 2 (a disarmed: its when still holds); a's when drops at 3,
    # inside b's mode, and that re-arms it; so a fires at 5, right after b's release at 4.
    assert _modes(c, points) == ["a", "free", "b", "b", "free", "a"]


def test_a_caught_ball_released_where_the_catch_guard_still_holds_flies_free(tmp_path):
    cfg = _ball_and_hand(tmp_path, "ball.h <= 1.5", "hand.y >= 0.9")
    run = run_project(cfg, tmp_path / "runs")
    rows = read_rows(run)
    t, h, v, hand = column(rows, "t"), column(rows, "ball.h"), column(rows, "ball.v"), column(rows, "hand.y")
    modes = [r["mode"] for r in rows]
    k_catch = next(k for k in range(len(rows)) if h[k] <= 1.5)
    k_release = next(k for k in range(k_catch + 1, len(rows)) if hand[k] >= 0.9)
    events = [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]
    assert [(e["step"], e["to"]) for e in events] == [(k_catch, "catch"), (k_release, "free")]
    assert h[k_release] <= 1.5 and modes[k_release:] == ["free"] * (len(rows) - k_release)
    for k in range(k_release + 1, len(rows)):  # its own dynamics again, not the hand's
        tau = t[k] - t[k_release]
        expected = h[k_release] + v[k_release] * tau - G * tau ** 2 / 2
        if expected <= 0:
            break
        assert math.isclose(h[k], expected, abs_tol=1e-9)


def test_a_guard_that_fails_at_run_time_stops_the_run_naming_event_and_step(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}],
        # parses and names real ports; divides by zero once clock.y passes 0.25
        events=[{"name": "odd", "when": "clock.y > 0.25 and 1 / (clock.y - clock.y) > 0", "drives": "g",
                 "until": "clock.y > 0.5"}],
        cosim={"stepSize": 0.1, "stopTime": 1.0})
    res = hycosim("run", str(cfg), "--runs-dir", str(tmp_path / "runs"), "--no-progress")
    assert res.returncode == 3, res.stderr
    assert "event 'odd': guard 'clock.y > 0.25 and 1 / (clock.y - clock.y) > 0' failed on" in res.stderr
    assert "division by zero (at step 3, t=0.3 s)" in res.stderr and "internal error" not in res.stderr
    run = next((tmp_path / "runs").iterdir())
    assert meta(run)["status"] == "failed" and len(read_rows(run)) == 3  # T_0..T_2 recorded
