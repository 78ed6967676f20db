"""Asynchronous sources: samples at their own rate, brought to macro-step points by hold or extrapolation."""

from __future__ import annotations

import math
import re

from hycosim.master.async_sources import SampleHistory
from tests.helpers import column, meta, read_rows, run_project, write_project


def test_sample_history_hold_and_linear():
    hist = SampleHistory([7.0])
    assert hist.value_at(0, 1.0, "linear") == (7.0, None)
    hist.add(0.1, [1.0])
    assert hist.value_at(0, 0.25, "linear") == (1.0, 0.15)
    hist.add(0.2, [2.0])
    value, age = hist.value_at(0, 0.25, "linear")
    assert math.isclose(value, 2.5) and math.isclose(age, 0.05)
    assert not hist.add(0.15, [9.0])  # older than the latest: ignored
    assert hist.value_at(0, 0.3, "hold")[0] == 2.0
    # A sample from ahead of the point (a paced run behind its source) waits for its time.
    hist.add(0.4, [4.0])
    assert hist.value_at(0, 0.3, "hold") == (2.0, 0.3 - 0.2)
    value, _ = hist.value_at(0, 0.3, "linear")
    assert math.isclose(value, 3.0)  # from 0.1 and 0.2, not through the sample at 0.4
    assert hist.at(0.3) == (0.2, [2.0]) and hist.at(0.45) == (0.4, [4.0])
    early = SampleHistory([0.0])
    early.add(0.5, [5.0])
    assert early.value_at(0, 0.3, "hold") == (5.0, 0.3 - 0.5)  # only newer samples: the oldest


def test_a_sample_stamped_at_no_finite_time_is_dropped_before_it_can_freeze_its_source():
    import pytest

    from hycosim.core import frames
    from hycosim.core.schema import Node
    from hycosim.master.intake import Dropped, Intake

    camera = Node.model_validate({"nodeName": "camera", "UID": 3, "async": True, "model": "ramp_source",
                                  "output": ["angle"]})
    intake = Intake([camera])
    hist = SampleHistory([0.0])
    for t in (math.inf, math.nan):
        with pytest.raises(Dropped, match="is not finite") as caught:
            intake.accept("camera", frames.encode(frames.SAMPLE, 3, 7, t, [1.0]))
        assert caught.value.reason == "wrong type"
    # What an infinite stamp would have done had it got through: every later sample ignored.
    hist.add(math.inf, [9.0])
    assert not hist.add(0.1, [1.0]) and hist.value_at(0, 0.1, "hold")[0] == 9.0
    accepted = intake.accept("camera", frames.encode(frames.SAMPLE, 3, 8, 0.1, [1.0]))
    assert (accepted.t, accepted.values) == (0.1, [1.0])


def test_extrapolated_and_held_samples_over_zenoh(tmp_path):
    rate, slope = 23.0, 2.0  # a rate that never lines up with the macro step
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "sensor", "UID": 1, "model": "ramp_source", "async": True, "rate": rate,
         "parameters": {"a": 0.5, "b": slope}, "output": ["y"]},
        {"nodeName": "lin", "UID": 2, "model": "gain", "input": ["u"], "output": ["y"]},
        {"nodeName": "zoh", "UID": 3, "model": "gain", "input": ["u"], "output": ["y"]},
    ], [{"from": "sensor.y", "to": "lin.u", "extrapolation": "linear"},
        {"from": "sensor.y", "to": "zoh.u", "extrapolation": "hold"}],
        cosim={"stepSize": 0.01, "stopTime": 1.0})
    run = run_project(cfg, tmp_path / "runs")
    rows = read_rows(run)
    timing = read_rows(run, "timing.csv")
    t, lin, zoh = column(rows, "t"), column(rows, "lin.u"), column(rows, "zoh.u")
    checked = 0
    for k in range(len(rows)):
        age_lin, age_zoh = timing[k]["age_s:lin.u"], timing[k]["age_s:zoh.u"]
        if not age_lin:
            assert lin[k] == 0.0 and zoh[k] == 0.0  # start values until the first sample
            continue
        assert float(age_lin) >= 0 and float(age_zoh) >= 0
        # Held: the value of the sample taken `age` ago.
        assert math.isclose(zoh[k], 0.5 + slope * (t[k] - float(age_zoh)), abs_tol=1e-5)
        sample_time = (zoh[k] - 0.5) / slope
        assert math.isclose(sample_time * rate, round(sample_time * rate), abs_tol=1e-6)
        if k >= 20:  # two samples in hand: a ramp is extrapolated exactly
            assert math.isclose(lin[k], 0.5 + slope * t[k], abs_tol=1e-9)
            checked += 1
    assert checked > 50
    assert meta(run)["samples_received"]["sensor"] >= int(rate * 0.9)
    # A source's last word counts what it sent: samples, not the steps it never takes.
    said = re.search(r"node 'sensor' finished after (\d+) samples", (run / "node-sensor.stderr.txt").read_text())
    assert said and int(said[1]) >= meta(run)["samples_received"]["sensor"], (run / "node-sensor.stderr.txt").read_text()


def test_real_time_pacing_keeps_its_pace_when_the_wall_clock_is_stepped(monkeypatch):
    """NTP stepping the clock back an hour mid-run used to stall pacing for that hour (the
    server slept until the wall clock caught up; its nodes gave up first)."""
    import time

    from hycosim.core.sim_clock import RealTimeClock

    clock = RealTimeClock(10.0, time.time() - 1.0, 2.0)  # started a second ago, at half speed
    assert abs(clock.now() - 10.5) < 0.05 and abs(clock.seconds_until(11.0) - 1.0) < 0.05
    wall = time.time
    for step_s in (-3600.0, 3600.0):
        monkeypatch.setattr(time, "time", lambda: wall() + step_s)
        assert abs(clock.now() - 10.5) < 0.05
        assert abs(clock.seconds_until(11.0) - 1.0) < 0.05
