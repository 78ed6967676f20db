"""The polynomials iterative coupling gives inputs over a step (server/interpolation.py)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hycosim.master.interpolation import InputTrack, taylor_derivatives
from tests.wire_strategies import values

coefficients = st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=4)
offsets = st.lists(st.floats(1e-3, 1.0), min_size=3, max_size=3)


@given(coefficients, offsets, st.floats(1e-4, 1.0))
def test_the_derivatives_are_those_of_the_polynomial_through_the_points(coef, gaps, scale):
    """Points before the step (uneven, as the short start-up steps leave them), the step's start
    at 0 and its end: a polynomial of at most their count's degree is found again exactly."""
    degree = len(coef) - 1
    taus = [-scale * (gaps[0] + gaps[1]), -scale * gaps[0], 0.0, scale * gaps[2]][3 - degree:]
    p = lambda s: sum(c * s ** j for j, c in enumerate(coef))  # noqa: E731
    got = taylor_derivatives(taus, [p(s) for s in taus])
    want = [math.factorial(j) * coef[j] for j in range(1, len(coef))]
    # The divided differences lose digits as the points close in: judged against the values' size.
    size = max(1.0, *(abs(c) for c in coef))
    assert got == pytest.approx(want, rel=1e-6, abs=1e-6 * size / scale ** degree)


def test_the_track_holds_then_extrapolates_and_starts_again_in_a_new_mode_or_an_earlier_time():
    track = InputTrack(3, ["b"])
    track.add(0.0, "free", {"a": [1.0, True], "b": [2.0, "x"]})
    assert track.first_guess(0.0, 0.1) == {"a": [1.0, True], "b": [2.0, "x"]}  # one point: held
    # Through the start and the end: a line. A Boolean or a String is no polynomial.
    assert track.slopes(0.0, 0.1, {"a": [1.5, True], "b": [3.0, "x"]}) == {"b": [pytest.approx([10.0]), None]}
    track.add(0.1, "free", {"a": [1.5, True], "b": [3.0, "x"]})
    assert track.first_guess(0.1, 0.1)["b"] == [pytest.approx(4.0), "x"]
    assert len(track.slopes(0.1, 0.1, {"a": [2.0, True], "b": [4.0, "x"]})["b"][0]) == 2
    track.add(0.2, "caught", {"a": [2.0, True], "b": [9.0, "x"]})  # another mode's inputs: no line through them
    assert track.first_guess(0.2, 0.1)["b"] == [9.0, "x"]
    track.add(0.3, "caught", {"a": [2.0, True], "b": [9.0, "x"]})
    track.add(0.1, "caught", {"a": [2.0, True], "b": [7.0, "x"]})  # a run taken back to a checkpoint
    assert track.snapshot()["points"] == [[0.1, {"a": [2.0, True], "b": [7.0, "x"]}]]


def test_a_checkpoints_points_come_back_as_they_were_saved():
    track = InputTrack(2, ["b"])
    for i in range(4):
        track.add(0.1 * i, "free", {"b": [float(i * i)]})
    again = InputTrack(2, ["b"])
    again.restore(track.snapshot())
    assert again.snapshot() == track.snapshot() and len(again.snapshot()["points"]) == 2
    assert again.slopes(0.3, 0.1, {"b": [16.0]}) == track.slopes(0.3, 0.1, {"b": [16.0]})


@given(values | st.fixed_dictionaries({"mode": values, "points": st.lists(
    st.lists(st.floats(allow_nan=True, allow_infinity=True) | values, max_size=3), max_size=4)}))
def test_points_read_from_a_checkpoint_file_are_checked(snapshot):
    track = InputTrack(3, ["b"])
    try:
        track.restore(snapshot)
    except ValueError:
        return
    points = track.snapshot()["points"]
    assert len(points) <= 3
    for t, inputs in points:
        assert type(t) is float and math.isfinite(t) and all(type(v) is list for v in inputs.values())
