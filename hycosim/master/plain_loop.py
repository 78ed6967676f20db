"""The relay's loop over the points of a plain run, flat.

A run is plain when nothing can happen at a point but routing the outputs and releasing the
step from it: the Jacobi scheme over frames, every node due at every point, one base step a
release, no events, no scenario, no asynchronous source, no checkpoints, no real-time pacing,
and nobody holding the points (a run from the command line). :func:`plain_plan` says whether
a run is one, once, where the relay plans it.

Each point of such a run is then what :meth:`Relay._arrive`, :meth:`Relay._step_from`,
Jacobi's step, :meth:`Barrier.exchange` and :meth:`Barrier.send` make of it, in one loop with
what it reads held in locals: the same STEP frames, the same rows in ``values.csv`` and
``timing.csv``, the same point to every observer and to the status answer, some thirty calls a
point fewer (benchmarks/FINDINGS.md, 2026-12-04). The answers are gathered by
:meth:`Barrier.gather`, the judge of every frame as in any run; whatever it raises (a node's
END, a node lost or restarted, a timeout) leaves this loop with the point recorded, as it
leaves the general one.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from hycosim.core import frames
from hycosim.master.barrier import Barrier, too_large
from hycosim.master.observers import RecordedPoint
from hycosim.master.plans import Plan
from hycosim.master.point_records import PointRecords
from hycosim.master.run_state import ModelEnded, Point, Progress, Rate
from hycosim.transport.session import FrameTooLarge


def plain_plan(*, scheme: str, events: bool, scenario: bool, sources: bool, checkpoints: bool,
               multirate: bool, span: int, calls: bool, paced: bool, held: bool) -> Plan:
    """Whether the points of a run are taken by :class:`PlainLoop`: only where each is a route
    and a release of every node (``scheme``: the master algorithm's words when it is not plain
    Jacobi, else ""; ``span``: base steps a release; ``calls``: steps as calls in process;
    ``paced``: a real-time run; ``held``: a caller holds each point)."""
    why = [w for on, w in ((bool(scheme), scheme), (events, "events"), (scenario, "a scenario"),
                           (sources, "asynchronous sources"), (checkpoints, "checkpoints"),
                           (multirate, "multi-rate"), (span > 1, "batched releases"), (calls, "steps as calls"),
                           (paced, "real time"), (held, "points held by a caller")) if on]
    if why:
        return Plan(False, f"each point through the algorithm ({', '.join(why)})", why=", ".join(why))
    return Plan(True, "plain: one flat loop over the points")


class PlainLoop:
    """The points of a plain run (:func:`plain_plan`), from a first point to the last."""

    def __init__(self, barrier: Barrier, records: PointRecords, progress: Progress, rate: Rate,
                 stop: threading.Event, mode: str):
        self.barrier, self.records, self.progress, self.rate = barrier, records, progress, rate
        self.stop, self.mode = stop, mode
        self._point = RecordedPoint(barrier.project)

    def run(self, p: Point, end: float) -> Point:
        """From point ``p`` (its outputs gathered) until the point at ``end`` (stopTime, less a
        tolerance) or a stop asked for: each point routed, recorded and, but for the last,
        stepped from. Return the last point, recorded. ModelEnded (the records of the node's
        end made), RunError and Recover leave as from the general loop."""
        b, mode, stop, record = self.barrier, self.mode, self.stop, self._record
        router, outputs, histories, stepping = b.router, b.outputs, b.histories, b.stepping
        inputs, route, gather, ledger, sent = router.inputs, router.route, b.gather, b.ledger, b.sent
        put, messages = b.release.put, b.messages
        H, stop_time, last_point = b.cosim.stepSize, b.cosim.stopTime, b.last_point
        encode, packed, VERSION, STEP = frames.encode, frames.packed, frames.VERSION, frames.STEP
        perf_counter, driven, no_slopes = time.perf_counter, [], {}
        # Every node gets every release: one that comes back is replayed the last (Barrier.replay).
        sent.of.clear()
        point = self._point  # what a plain run's every point has alike (Relay._arrive's Seen for it)
        point.mode, point.inputs, point.stepped, point.lateness_s, point.takes = mode, inputs, None, None, 1
        k, t, origin, j, arrivals, wait = p.k, p.t, p.origin, p.j, p.arrivals, p.wait
        while True:
            b.point = k
            ages = route(mode, t, outputs, histories)
            holder = max(arrivals, key=arrivals.get) if arrivals else ""
            seen = dict(outputs)  # the step replaces them before point k is recorded
            if t >= end or stop.is_set():
                record(k, t, seen, wait, holder, arrivals, ages)
                return Point(k, t, origin, j, {}, arrivals, wait)
            next_t = min(origin + (j + 1) * H, stop_time)
            # Barrier.send's, flat: every node is released, and the inputs hold no other node's.
            released = perf_counter()
            try:
                try:  # frames.encode's packing, without its call
                    frame = packed((VERSION, STEP, k, t, next_t - t, mode, inputs, driven, no_slopes))
                except TypeError:
                    frame = encode(STEP, k, t, next_t - t, mode, inputs, driven, no_slopes)
                sent.last = frame
                try:
                    put(frame)
                except FrameTooLarge as exc:
                    raise too_large(k, t, inputs, exc) from None
                messages["releases"] += 1
                ledger.released(stepping, k, released, last_point=last_point)
            finally:  # recorded while the nodes step; also where the release failed
                record(k, t, seen, wait, holder, arrivals, ages)
            try:
                arrivals = gather(k + 1, released)
            except ModelEnded:
                self.records.end(k, mode, seen, [t, next_t])
                raise
            wait = perf_counter() - released
            k, t, j = k + 1, next_t, j + 1

    def _record(self, k: int, t: float, seen: dict[str, list[Any]], wait: float, holder: str,
                arrivals: dict[str, float], ages: dict[str, float | None]) -> None:
        """Point k recorded and shown, as :meth:`Relay._record_point` does: the progress, the
        rate, every observer (the recorder, the status answer, a user's)."""
        progress, now = self.progress, time.perf_counter()
        progress.step, progress.t, progress.mode, progress.lateness_s = k, t, self.mode, None
        self.rate.point(progress, k, now)
        point = self._point
        point.outputs, point.wait_s, point.holder, point.arrivals, point.ages, point.released = (
            seen, wait, holder, arrivals, ages, now)
        self.records.tell(k, t, point)
