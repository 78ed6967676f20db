"""What the status answer says of the run's latest points: the barrier over the last second,
and the points a dashboard has not yet plotted.

The answer is built in Zenoh's thread under the GIL, so the server's loop waits while it is
built. Reckoning every point of the last second and sending 256 points took 6 ms an answer on
2 cores at 3,000 steps/s: at five answers a second, 3 % of the run's time, which the run lost
(benchmarks/dashboard_cost.py). Samples drawn from the second, and fewer points, take a third of
that (2.0 ms) and show the same.

Nor does it take every point: at most one a millisecond (:data:`TAKE_EVERY_S`), and the run's
last at its end. Copying each point's values cost 0.6 µs a point hot at 2 nodes and, in whole
runs, where the loop runs cold, up to 5 µs of the server's 60, at 15,000 points a second
(benchmarks/FINDINGS.md, tenth and eleventh entries); a dashboard plots at most 320 points a
second of them. The steps a second are counted from every point told, taken or not.
"""

from __future__ import annotations

import bisect
import math
import random
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from itertools import chain
from operator import itemgetter
from typing import Any

from hycosim.core.schema import FREE_MODE, Project
from hycosim.master.observers import RecordedPoint, node_lists

# At most this many points an answer (at five answers a second, 320 a second: more than a plot
# a thousand pixels wide keeps of a run past its first seconds).
STATUS_POINTS = 64
# The barrier's shares and mean arrivals are reckoned from at most this many of the second's points,
# drawn at random: every k-th point would see one node only where the nodes take turns (a
# multi-rate run, Gauss-Seidel). A share from 256 draws is within 0.03 of the second's (sd).
WINDOW_SAMPLES = 256
# A point is taken at most this often (s); the points between are only counted.
TAKE_EVERY_S = 0.001

_flat = chain.from_iterable

# A recent point: (perf_counter at its release, the node the barrier waited for last, how long
# it waited, each node's arrival after the release, how many points with a release had been
# told by then, this one among them), in time order.
Recent = tuple[float, str, float, dict[str, float], int]


def barrier_window(recent: Sequence[Recent], now: float, kept: int) -> dict[str, Any]:
    """Steps in the second before ``now``, each node's share of the barrier held and its mean
    arrival (ms); ``kept``: how many points ``recent`` holds at most. The steps are counted
    from the first point kept in the second to the last, those not kept between them among them;
    when the kept points do not reach a second back, the steps are the rate over them."""
    first = bisect.bisect_left(recent, now - 1.0, key=itemgetter(0))
    in_second = len(recent) - first
    steps = recent[-1][4] - recent[first][4] + 1 if in_second else 0
    if first == 0 and len(recent) >= kept > 1 and now > recent[0][0]:
        steps = round((recent[-1][4] - recent[0][4]) / (now - recent[0][0]))
    held: dict[str, float] = {}
    arrived: dict[str, list[float]] = {}
    drawn = range(first, len(recent))
    if in_second > WINDOW_SAMPLES:  # seeded by the count: the same points give the same answer
        drawn = random.Random(in_second).sample(drawn, WINDOW_SAMPLES)
    for i in drawn:
        _, holder, wait, arrivals, _ = recent[i]
        if holder:
            held[holder] = held.get(holder, 0.0) + wait
        for node, at in arrivals.items():
            arrived.setdefault(node, []).append(at)
    total = sum(held.values())
    return {"steps": steps, "held": {n: w / total for n, w in held.items()} if total > 0 else {},
            "arrival_ms": {n: 1000 * sum(a) / len(a) for n, a in arrived.items()}}


def points_since(history: Sequence[tuple], since: int) -> list[list[Any]]:
    """``[step, t, outputs, inputs]`` of the kept points ``(step, t, mode, outputs, inputs,
    wall)`` after step ``since``, evenly thinned to at most STATUS_POINTS, the latest among them."""
    points = [p for p in history if p[0] > since]
    stride = -(-len(points) // STATUS_POINTS)
    kept = points[::-1][::stride][::-1] if stride > 1 else points
    return [[k, t, outputs, inputs] for k, t, _, outputs, inputs, _ in kept]


class Layout:
    """Every node's values of one side (outputs or inputs) as one flat tuple, the nodes in the
    project's order and each node's ports in its own: what the status answer keeps of a point.
    A point kept as the mappings it came in held a dict and a list a node (the values' lists
    of the nodes' frames, with them) for 4,096 points: objects the cyclic collector walked
    until they died, some 3 µs a step at 8 nodes (benchmarks/FINDINGS.md, 2026-12-04, fifth
    entry); tuples of numbers it stops tracking."""

    def __init__(self, widths: Sequence[tuple[str, int]]):
        self.names = [name for name, _ in widths]
        # Every node's list of values, as a tuple in the project's order.
        self.lists: Callable[[Mapping[str, list[Any]]], tuple[list[Any], ...]] = node_lists(self.names)
        self._slices: list[tuple[str, int, int]] = []
        i = 0
        for name, width in widths:
            self._slices.append((name, i, i + width))
            i += width

    def nodes(self, flat: Sequence[Any] | None) -> dict[str, list[Any]]:
        """Each node's values again from ``tuple(chain.from_iterable(self.lists(values)))``
        ({} for None: no point yet)."""
        if flat is None:
            return {}
        return {name: list(flat[a:b]) for name, a, b in self._slices}


class LatestPoints:
    """The run's latest points as the status answer shows them (``hycosim status``, the
    dashboard's feed): an observer of the run's points, to which the loop adds each mode switch
    too; Zenoh's thread reads them for an answer, each a copy taken at once under the GIL."""

    def __init__(self, project: Project, kept: int, every_s: float = TAKE_EVERY_S):
        self.kept, self.every_s = kept, every_s
        self._outputs = Layout([(n.nodeName, len(n.output)) for n in project.nodeLists])
        self._inputs = Layout([(n.nodeName, len(n.input)) for n in project.nodeLists])
        self.recent: deque[Recent] = deque(maxlen=kept)  # for the barrier window
        # (step, t, mode, outputs, inputs, wall), the values flat (Layout), for the dashboard
        self.history: deque[tuple] = deque(maxlen=kept)
        # Before the first point: no values to show.
        self.shown: tuple[int, float, str, tuple[Any, ...] | None, tuple[Any, ...] | None, float | None] = (
            0, project.coSimulation.startTime, FREE_MODE, None, None, None)
        self.ages: dict[str, float | None] = {}  # each asynchronous value's age at the latest point
        self.switches: deque[dict[str, Any]] = deque(maxlen=200)  # the latest mode switches
        self._told = 0  # points with a release told, taken or not
        self._due = -math.inf  # perf_counter from which a point with a release is taken again
        # The latest point told and not taken, if the latest told was not: taken at the run's end.
        self._left: tuple[int, float, RecordedPoint] | None = None

    # --- an observer of the run's points (master.observers) --------------------------

    def step_complete(self, step: int, t: float, point: RecordedPoint) -> None:
        """Point ``step`` as recorded, taken if the last was taken ``every_s`` before its release
        or more (or it had no release of its own): its values whole (copies: the loop goes on
        changing them), and where a release left from it, how the barrier held it."""
        released = point.released
        if released is not None:
            self._told += 1
            if released < self._due:
                self._left = (step, t, point)
                return
            self._due = released + self.every_s
        self._take(step, t, point)

    def _take(self, step: int, t: float, point: RecordedPoint) -> None:
        """Point ``step`` kept: in the barrier window (with the points told by then) where a
        release left from it, and shown."""
        if point.released is not None:
            self.recent.append((point.released, point.holder, point.wait_s, point.arrivals, self._told))
            self.ages = point.ages
        self._left = None
        # Each side's values flat, in the project's order (Layout).
        self.shown = (step, t, point.mode, tuple(_flat(self._outputs.lists(point.outputs))),
                      tuple(_flat(self._inputs.lists(point.inputs))), time.time())
        self.history.append(self.shown)

    def state_restored(self, step: int, t: float) -> None:
        """Back at point ``step``: the points from it on come again, and are shown again."""
        while self.history and self.history[-1][0] >= step:
            self.history.pop()
        if self._left is not None and self._left[0] >= step:
            self._left = None

    def run_ended(self, status: str) -> None:
        """The run's last point taken, if it was not (the master's point still holds it: nothing
        is routed after it); it stays the answer's, for whoever asks while the run closes."""
        if self._left is not None:  # the latest told: the points told by then are all there were
            self._take(*self._left)

    def answer(self, now: float, since: int | None) -> dict[str, Any]:
        """The status answer's part on the latest points (``since``: also the points after that step)."""
        k, t, mode, outputs, inputs, wall = self.shown
        out, into = self._outputs.nodes, self._inputs.nodes
        points = None if since is None else [[step, at, out(o), into(i)] for step, at, o, i in
                                             points_since(list(self.history), since)]
        return {"step": k, "t": t, "mode": mode, "switches": list(self.switches),
                "window": barrier_window(list(self.recent), now, self.kept),
                "outputs": out(outputs), "inputs": into(inputs), "point_wall": wall, "ages": dict(self.ages),
                **({} if since is None else {"points": points})}
