"""The hybrid coordinator: a guard fires, the driven node follows its driver, release resumes free dynamics."""

from __future__ import annotations

import json
import math

from tests.helpers import column, read_rows, run_project, write_project

G = 9.81
H = 0.01


def test_catch_and_release_of_a_falling_ball(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "ball", "UID": 1, "model": "bouncing_ball", "parameters": {"h0": 2.0, "v0": 0.0, "g": G, "e": 0.8},
         "input": ["h_in", "v_in"], "output": ["h", "v", {"name": "impacts", "type": "Integer"}]},
        {"nodeName": "hand", "UID": 2, "model": "ramp", "parameters": {"a": 0.2, "b": 0.5}, "output": ["y", "v"]},
    ], [{"from": "hand", "to": "ball", "pairs": [["y", "h_in"], ["v", "v_in"]], "activeIn": ["catch"]}],
        events=[{"name": "catch", "when": "ball.h <= hand.y and hand.y < 1.0", "drives": "ball", "until": "hand.y >= 1.2"}],
        cosim={"stepSize": H, "stopTime": 2.4})
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
