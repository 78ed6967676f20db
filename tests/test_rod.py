"""The MuJoCo rod: period, damping, driven-mode continuity, observer correction, its FMU."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from hycosim.scenario.rod.model import RodModel, RodParams, pendulum_period


def _period(rod: RodModel, seconds: float = 6.0) -> float:
    turns = []
    while rod.time < seconds:
        w0 = rod.omega
        rod.advance(rod.model.opt.timestep)
        w1 = rod.omega
        if (w0 > 0) != (w1 > 0) and w0 != 0:
            turns.append(rod.time - rod.model.opt.timestep * abs(w1) / (abs(w0) + abs(w1)))
    return (turns[-1] - turns[0]) / ((len(turns) - 1) / 2)


@pytest.mark.parametrize("deg", [30, 40, 50, 60])
def test_period_matches_the_large_angle_physical_pendulum(deg):
    p = RodParams(damping=0.0, initial_angle=math.radians(deg))
    measured = _period(RodModel(p))
    expected = pendulum_period(p, math.radians(deg))
    assert abs(measured / expected - 1) < 0.005
    small = pendulum_period(p, 1e-6)
    assert expected > small * (1 + (math.radians(deg) ** 2) / 16 * 0.9)  # the correction matters here


def test_damping_dissipates_energy_monotonically_and_none_without_it():
    damped = RodModel(RodParams(damping=0.01, initial_angle=math.radians(50)))
    e = [damped.energy()]
    for _ in range(300):
        damped.advance(0.01)
        e.append(damped.energy())
    assert all(b <= a + 1e-9 for a, b in zip(e, e[1:]))
    assert e[-1] < 0.9 * e[0]
    free = RodModel(RodParams(damping=0.0, initial_angle=math.radians(50)))
    e0 = free.energy()
    free.advance(3.0)
    assert abs(free.energy() / e0 - 1) < 1e-3


def test_driven_mode_is_continuous_at_both_switches_and_follows_the_gripper():
    rod = RodModel(RodParams(initial_angle=math.radians(40)))
    rod.advance(0.2)
    before = (rod.angle, rod.omega)
    rod.set_gripper(rod.point(rod.p.grasp_distance))  # the gripper takes the rod where it is
    rod.set_driven(True)
    rod.advance(0.001)
    assert abs(rod.angle - before[0]) < 0.01 and abs(rod.omega - before[1]) < 0.3  # no jump at the switch
    target = -0.3
    rod.set_gripper(rod.point(rod.p.grasp_distance, target))
    rod.advance(1.0)
    assert abs(rod.angle - target) < 0.01  # follows the gripper
    held = (rod.angle, rod.omega)
    rod.set_driven(False)
    rod.advance(0.001)
    assert abs(rod.angle - held[0]) < 0.001 and abs(rod.omega - held[1]) < 0.1  # continuous on release
    rod.advance(0.3)
    assert abs(rod.omega) > 0.3  # swinging freely again


def test_observer_pulls_the_twin_onto_the_measured_rod_and_gain_zero_does_not():
    truth = RodModel(RodParams(length=0.63, initial_angle=math.radians(43)))
    twin = RodModel(RodParams(initial_angle=math.radians(40), observer_gain=8.0))
    blind = RodModel(RodParams(initial_angle=math.radians(40), observer_gain=0.0))
    h = 0.01
    errors, blind_errors = [], []
    for _ in range(300):
        for m in (twin, blind):
            m.correct(truth.angle, h)
            m.advance(h)
        truth.advance(h)
        errors.append(abs(twin.angle - truth.angle))
        blind_errors.append(abs(blind.angle - truth.angle))
    assert max(errors[-50:]) < math.radians(1.0)
    assert max(blind_errors[-50:]) > math.radians(3.0)
    assert errors[-1] < errors[0] / 3


def test_a_measurement_captured_ahead_of_the_twin_waits_until_the_twin_reaches_its_time():
    twin = RodModel(RodParams(initial_angle=math.radians(40), observer_gain=12.0))
    free = RodModel(RodParams(initial_angle=math.radians(40)))
    twin.advance(0.1)
    free.advance(0.1)
    truth_later = math.radians(20)  # what a camera saw at t = 0.2, while the twin is at 0.1
    twin.correct(truth_later, 0.01, measured_at=0.2)
    assert (twin.angle, twin.omega) == (free.angle, free.omega)  # not dragged towards the future
    for _ in range(10):
        twin.advance(0.01)
        free.advance(0.01)
    twin.correct(truth_later, 0.01, measured_at=0.2)  # the same sample, still routed: now it applies
    assert twin.angle != free.angle
    assert abs(twin.angle - truth_later) < abs(free.angle - truth_later)


def test_a_measurement_ahead_of_the_twin_is_used_once_reached_though_a_newer_one_replaced_it():
    twin = RodModel(RodParams(initial_angle=math.radians(40), observer_gain=12.0))
    free = RodModel(RodParams(initial_angle=math.radians(40)))
    for m in (twin, free):
        m.advance(0.1)
    twin.correct(math.radians(20), 0.01, measured_at=0.15)  # ahead of the twin: it waits
    for m in (twin, free):
        m.advance(0.03)
    twin.correct(math.radians(21), 0.01, measured_at=0.17)  # a newer frame on the input, also ahead
    assert (twin.angle, twin.omega) == (free.angle, free.omega)
    for m in (twin, free):
        m.advance(0.03)
    # At 0.16 the frame of 0.15 is reached; the input still carries the one of 0.17.
    twin.correct(math.radians(21), 0.01, measured_at=0.17)
    assert twin.angle < free.angle  # pulled towards 20° by the frame the input no longer carries


@pytest.mark.parametrize("delay_s", [0.05, 0.1])
def test_the_observer_stays_on_the_rod_with_frames_in_flight(delay_s):
    """Frames at 60 per second reach the twin ``delay_s`` after their capture (a loaded machine):
    each compared with the twin at its capture time, and each error corrected once."""
    truth = RodModel(RodParams(length=0.63, initial_angle=math.radians(43)))
    twin = RodModel(RodParams(initial_angle=math.radians(40), observer_gain=12.0))
    h, frames, errors = 0.01, [], []
    for k in range(250):
        t = k * h
        while not frames or frames[-1][0] + 1 / 60 <= t + 1e-9:
            frames.append((len(frames) / 60, None))
        seen = [f for f in frames if f[0] <= t - delay_s]
        if seen:
            at = seen[-1][0]
            twin.correct(truth.angle_at(at), h, measured_at=at)
        twin.advance(h)
        truth.advance(h)
        errors.append(abs(twin.angle - truth.angle))
    # Corrected once per frame in flight the twin swung off (98° at 50 ms) or away (at 100 ms);
    # uncorrected it is 10° off. Late frames leave it 0.4-0.5° off here.
    assert sum(errors[-50:]) / 50 < math.radians(1.0), [round(math.degrees(e), 2) for e in errors[::25]]


_times = st.floats(allow_nan=True, allow_infinity=True)


@given(last=_times, pending=st.lists(_times, max_size=8))
@example(last=-1.0, pending=[0.0, 0.0])  # a queued frame that pulls the twin the other way first
def test_a_saved_state_with_any_measurement_times_restores_only_an_ordered_queue(last, pending):
    rod = RodModel(RodParams(initial_angle=math.radians(40), observer_gain=12.0))
    rod.advance(0.05)
    snap = {**rod.snapshot(), "last_measurement": last, "pending": pending}
    try:
        rod.restore(snap)
    except ValueError:
        return
    times = [rod._last_measurement, *(t for t, _ in rod._pending)]
    assert not math.isnan(times[0]) and all(math.isfinite(t) for t in times[1:])
    assert all(a < b for a, b in zip(times, times[1:]))
    # And the observer goes on: a frame of the twin's present is used, after those queued,
    # unless one as late or later was had.
    rod.correct(rod.angle + 0.1, 0.01, measured_at=rod.time)
    assert rod._last_measurement == rod.time or times[-1] >= rod.time
    assert not rod._pending or rod._pending[0][0] > rod.time


@given(where=st.integers(min_value=0), value=st.one_of(st.sampled_from([math.nan, math.inf, -math.inf]),
                                                      st.floats(min_value=1e10, exclude_min=True),
                                                      st.floats(max_value=-1e10, exclude_max=True)))
def test_a_saved_state_with_a_value_mujoco_would_reset_is_refused(where, value):
    rod = RodModel(RodParams(initial_angle=math.radians(40), observer_gain=12.0))
    rod.advance(0.05)
    snap = rod.snapshot()
    snap["mujoco"][where % len(snap["mujoco"])] = value
    with pytest.raises(ValueError, match="not a state of this rod"):
        rod.restore(snap)


_bad = st.sampled_from([math.nan, math.inf, -math.inf])


@given(frames=st.lists(st.one_of(st.tuples(_bad, st.one_of(st.none(), _times)), st.tuples(_times, _bad)),
                       min_size=1, max_size=12))
def test_a_nan_or_infinite_measurement_leaves_the_twin_as_if_it_had_not_come(frames):
    twin = RodModel(RodParams(initial_angle=math.radians(40), observer_gain=12.0))
    free = RodModel(RodParams(initial_angle=math.radians(40)))
    for angle, at in frames:
        twin.correct(angle, 0.01, measured_at=at)
        for m in (twin, free):
            m.advance(0.01)
        assert (twin.angle, twin.omega) == (free.angle, free.omega), (angle, at)


_finite = st.floats(allow_nan=False, allow_infinity=False)


@given(frames=st.lists(st.tuples(_finite, _finite), min_size=1, max_size=6))
@example(frames=[(1e300, 0.0)])              # an angle MuJoCo would call unstable and reset
@example(frames=[(0.0, 1e300), (0.0, 0.0)])  # a frame from far in the future, then good ones
def test_after_any_finite_frames_the_camera_brings_the_twin_onto_the_rod(frames):
    """Whatever finite angles and capture times a node sends first, the twin is never reset
    (MuJoCo resets a state it finds unstable, and time with it) and later good frames bring it
    onto the rod: an angle error counts modulo a turn, and a frame stamped in the future does
    not hold back those after it."""
    truth = RodModel(RodParams(length=0.63, initial_angle=math.radians(43)))
    twin = RodModel(RodParams(initial_angle=math.radians(40), observer_gain=12.0))
    h, errors = 0.01, []
    for k in range(300):
        angle, at = frames[k] if k < len(frames) else (truth.angle, twin.time)
        twin.correct(angle, h, measured_at=at)
        for m in (twin, truth):
            m.advance(h)
        errors.append(abs(math.remainder(twin.angle - truth.angle, 2 * math.pi)))
    assert twin.time == pytest.approx(truth.time)
    assert twin.data.warning[mujoco.mjtWarning.mjWARN_BADQPOS].number == 0
    assert max(errors[-50:]) < math.radians(1.0), [round(math.degrees(e), 2) for e in errors[::25]]


@given(grips=st.lists(st.tuples(_times, _times, _times), min_size=1, max_size=5),
       goal=st.floats(min_value=-math.radians(80), max_value=math.radians(80)))
@example(grips=[(0.62, 1e3, 1.0)], goal=0.0)   # a kilometre off: the equality spun the rod
@example(grips=[(0.62, 1e300, 1.0)], goal=0.0)  # the force overflowed and MuJoCo reset the rod
def test_a_driven_rod_given_any_gripper_positions_is_never_reset_and_still_follows(grips, goal):
    rod = RodModel(RodParams(initial_angle=math.radians(40)))
    rod.advance(0.1)
    rod.set_driven(True)
    for grip in grips:
        rod.set_gripper(np.array(grip))
        for _ in range(5):
            rod.advance(0.01)
    rod.set_gripper(rod.point(rod.p.grasp_distance, goal))
    for _ in range(100):
        rod.advance(0.01)
    assert rod.time == pytest.approx(0.1 + 0.05 * len(grips) + 1.0)  # MuJoCo resets time with the state
    assert not any(rod.data.warning[w].number for w in (mujoco.mjtWarning.mjWARN_BADQPOS,
                                                         mujoco.mjtWarning.mjWARN_BADQVEL,
                                                         mujoco.mjtWarning.mjWARN_BADQACC))
    assert abs(math.remainder(rod.angle - goal, 2 * math.pi)) < math.radians(1.0)


def test_grasp_and_tip_positions_follow_the_angle():
    rod = RodModel(RodParams(initial_angle=math.radians(30)))
    o = rod.outputs()
    pivot = np.array(rod.p.pivot)
    assert np.allclose(o.grasp, pivot + rod.p.grasp_distance * np.array([0, math.sin(o.angle), -math.cos(o.angle)]), atol=1e-9)
    assert np.allclose(o.tip, pivot + rod.p.length * np.array([0, math.sin(o.angle), -math.cos(o.angle)]), atol=1e-9)
