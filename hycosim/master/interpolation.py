"""Inputs that move over a step: the polynomials iterative coupling gives the nodes that can
interpolate their inputs (coSimulation.iterate.interpolate; an FMI 2 FMU's
fmi2SetRealInputDerivatives, ``canInterpolateInputs``).

Held over a step, an input is off by O(h) inside it, and the coupled solution is first order
in the macro step whatever the nodes' own solvers do. Over the step from t to t + h, a Real
input here follows the polynomial of degree n through the end value the iteration solves for
and the values routed at the n points before it (t among them): off by O(h^(n+1)) inside the
step, so the coupling is of order n + 1 (measured in benchmarks/accuracy.py). The node gets
the polynomial as its derivatives at t (orders 1 to n, the Taylor coefficients times their
factorials), the FMI form.

Points come from one mode: a mode switch changes what the inputs are (a driven node's), so the
history starts again there. A checkpoint keeps the points (snapshot, restore), so that a run
taken back to it steps as it did. Until the history holds n points the degree is lower; the relay takes the first steps of a run shorter (STARTUP_SPLIT) so that those
low-degree steps do not spoil the order.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping
from typing import Any

# The first (degree − 1) macro steps of a run are taken as this many steps each: a step on a
# polynomial of degree m < n errs by O(h^(m+2)), STARTUP_SPLIT^(m+1) times less at h / STARTUP_SPLIT.
STARTUP_SPLIT = 8
MAX_DEGREE = 3  # coSimulation.iterate.interpolate's highest (frames.MAX_SLOPE_ORDER derivatives)


def _coefficients(taus: list[float], values: list[float]) -> list[float]:
    """The monomial coefficients a_0 … a_m of the polynomial through (taus[i], values[i])."""
    m = len(taus)
    c = list(values)  # Newton's divided differences, in place
    for j in range(1, m):
        for i in range(m - 1, j - 1, -1):
            c[i] = (c[i] - c[i - 1]) / (taus[i] - taus[i - j])
    poly = [c[-1]]  # Horner on the Newton form: poly·(τ − taus[i]) + c[i]
    for i in range(m - 2, -1, -1):
        shifted = [0.0] + poly
        for j, a in enumerate(poly):
            shifted[j] -= taus[i] * a
        shifted[0] += c[i]
        poly = shifted
    return poly


def taylor_derivatives(taus: list[float], values: list[float]) -> list[float]:
    """The derivatives at τ = 0, orders 1 … m − 1, of the polynomial through the m points."""
    a = _coefficients(taus, values)
    return [math.factorial(j) * a[j] for j in range(1, len(a))]


def _evaluate(taus: list[float], values: list[float], at: float) -> float:
    return sum(a * at ** j for j, a in enumerate(_coefficients(taus, values)))


def _floats(column: Iterable[Any]) -> bool:
    return all(type(v) is float and math.isfinite(v) for v in column)


class InputTrack:
    """The inputs routed at the last points, and the polynomials through them for a step."""

    def __init__(self, degree: int, nodes: Iterable[str]):
        self.degree = degree
        self.nodes = sorted(nodes)  # those that interpolate
        self._points: deque[tuple[float, dict[str, list[Any]]]] = deque(maxlen=degree)
        self._mode: str | None = None

    def clear(self) -> None:
        """Forget the points kept (a new mode, a rollback, a restore)."""
        self._points.clear()

    def add(self, t: float, mode: str, inputs: Mapping[str, list[Any]]) -> None:
        """The inputs routed at point t (before its step): a new point of the history."""
        if mode != self._mode or (self._points and t <= self._points[-1][0]):
            self._points.clear()  # another mode's inputs, or a run taken back to an earlier point
        self._mode = mode
        self._points.append((t, {n: list(v) for n, v in inputs.items()}))

    def first_guess(self, t: float, h: float) -> dict[str, list[Any]]:
        """Every node's inputs at t + h, extrapolated from the points (held from the last where
        there is one point, or the input is no float)."""
        latest = self._points[-1][1]
        taus = [p - t for p, _ in self._points]
        guess: dict[str, list[Any]] = {}
        for node, now in latest.items():
            out = list(now)
            if len(taus) > 1:
                for i in range(len(now)):
                    column = [values[node][i] for _, values in self._points]
                    if _floats(column):
                        out[i] = _evaluate(taus, column, h)
            guess[node] = out
        return guess

    def slopes(self, t: float, h: float, end: Mapping[str, list[Any]]) -> dict[str, list[list[float] | None]]:
        """For each interpolating node, per input: the derivatives at t of the polynomial through
        the points and ``end`` at t + h; None for an input that is no float at every one."""
        taus = [p - t for p, _ in self._points] + [h]
        out: dict[str, list[list[float] | None]] = {}
        for node in self.nodes:
            row: list[list[float] | None] = []
            for i, last in enumerate(end[node]):
                column = [values[node][i] for _, values in self._points] + [last]
                derivatives = taylor_derivatives(taus, column) if _floats(column) else None
                row.append(derivatives if derivatives and _floats(derivatives) else None)
            out[node] = row
        return out

    def snapshot(self) -> dict[str, Any]:
        """The points and their mode, for a checkpoint (msgpack-able)."""
        return {"mode": self._mode, "points": [[t, {n: list(v) for n, v in values.items()}] for t, values in self._points]}

    def restore(self, snapshot: Any) -> None:
        """The points of a snapshot (from a checkpoint file: checked); ValueError if it is none."""
        points = snapshot.get("points") if type(snapshot) is dict else None
        mode = snapshot.get("mode") if type(snapshot) is dict else None
        if not (type(points) is list and len(points) <= self.degree and (mode is None or type(mode) is str)
                and all(type(p) is list and len(p) == 2 and type(p[0]) is float and math.isfinite(p[0])
                        and type(p[1]) is dict and all(type(v) is list for v in p[1].values()) for p in points)):
            raise ValueError("its interpolated inputs' points are not a list of [time, {node: [values]}]")
        self._mode = mode
        self._points.clear()
        self._points.extend((t, values) for t, values in points)

    def start(self) -> dict[str, list[Any]]:
        """The inputs at the step's start (the last point's)."""
        return {n: list(v) for n, v in self._points[-1][1].items()}
