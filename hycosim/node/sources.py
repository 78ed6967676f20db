"""Nodes that do not step: an asynchronous source sampling on its own clock, and a recorded
source played back in step with the run (its samples for each point sent before the point)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hycosim.core import frames
from hycosim.core.schema import CoSimulation, Node as NodeSpec
from hycosim.core.sim_clock import RealTimeClock
from hycosim.node.interface import AsyncSource, NodeModelError
from hycosim.node.receiving import NodeRunError, Receiver
from hycosim.node.replay import SamplePlayer
from hycosim.node.sending import Outbox

OnStop = Callable[[frames.Frame], None]


def source_start(receiver: Receiver, cosim: CoSimulation) -> tuple[frames.Frame, bool]:
    """An asynchronous source's START (a restarted one's too: a source has no state to restore),
    and whether it came as a replay (to a process that replaces one)."""
    start = receiver.wait(cosim.attachTimeout + cosim.stepTimeout, "START")
    returning = False
    if start.kind == frames.REPLAY:
        returning, start = True, start.release
    if start.kind not in (frames.START, frames.STOP):
        at = f" (step {start.step})" if start.kind in (frames.STEP, frames.STEPS) else ""
        raise NodeRunError(f"node {receiver.name!r}: the run on {receiver.endpoint} was already under way{at} "
                           "when it attached; a node joins before the run starts")
    return start, returning


def run_source(impl: AsyncSource, spec: NodeSpec, cosim: CoSimulation, start: frames.Frame, outbox: Outbox,
               receiver: Receiver, on_stop: OnStop, log: Any) -> int:
    """Sample until the run's STOP: on the wall clock (a real-time run) or at each release's
    end (as fast as possible). Return the samples sent."""
    t0, wall0, rt = start.t0, start.wall_t0, start.real_time_factor
    clock = RealTimeClock(t0, wall0, rt) if rt else None
    sim_now, seq = t0, 0
    period = 1.0 / float(spec.rate or 30.0)
    while True:
        try:
            for ts, values in impl.samples_until(sim_now):
                outbox.send(frames.encode(frames.SAMPLE, spec.UID, seq, ts, outbox.pack(values)))
                seq += 1
        except Exception as exc:
            _source_failed(exc, sim_now, spec, outbox, log)
        if clock is not None:
            # Real time: sample by the clock, and look for STOP in between. While the
            # server is away (within linkGrace) samples go nowhere; sampling goes on.
            frame = receiver.next_frame(period)
            sim_now = clock.now()
        else:
            # As fast as possible: the server's releases are the clock.
            frame = receiver.wait(cosim.stepTimeout + 30.0, "release")
            if frame.kind == frames.REPLAY:
                frame = frame.release
            if frame.kind == frames.STEP:
                sim_now = frame.t + frame.h
                outbox.steps = frame.step + 1
        if frame is not None and frame.kind == frames.STOP:
            on_stop(frame)
            return seq


def _source_failed(exc: Exception, sim_now: float, spec: NodeSpec, outbox: Outbox, log: Any) -> None:
    """Tell the server how an asynchronous source failed (it would otherwise learn only that
    its token went, and with a link grace wait that long to say so), then raise it."""
    if isinstance(exc, NodeRunError):
        message = str(exc)
    elif isinstance(exc, NodeModelError):
        message = f"{exc} (at t={sim_now:g} s)"
    else:
        log.exception("source failed", t=sim_now)
        message = (f"node {spec.nodeName!r} (an asynchronous source): its model failed at t={sim_now:g} s: "
                   f"{type(exc).__name__}: {exc}")
    outbox.end(outbox.steps + 1, sim_now, False, message)


@dataclass
class Played:
    """A recording played in step with the run: the held outputs it sends (start values: the
    server ignores them), the last point whose samples are sent, the next sample's number."""

    impl: SamplePlayer
    uid: int
    outbox: Outbox
    held: list[Any]
    sent: int
    seq: int = 0

    def on_frame(self, frame: frames.Frame) -> None:
        """Send the samples due by the point a release reaches, then the word that they are sent."""
        if frame.kind == frames.REPLAY:
            frame = frame.release
        point: int | None = None
        if frame.kind == frames.START and self.sent < 0:
            point, t = 0, frame.t0
        elif frame.kind == frames.STEP:
            point, t = frame.step + 1, frame.t + frame.h
        elif frame.kind == frames.RESTORE:
            point, t = frame.step, frame.t
            self.sent = point  # the server's restored histories hold what came before
        if point is None:  # a CHECKPOINT, ROLLBACK or the START a resume sends again
            return
        for sample in self.impl.due(self.sent, point):
            self.outbox.send(frames.encode(frames.SAMPLE, self.uid, self.seq, sample.t,
                                           self.outbox.pack(self.impl.values(sample))))
            self.seq += 1
        self.sent = max(self.sent, point)
        self.outbox.send(frames.encode(frames.OUTPUTS, self.uid, point, t, self.held))
        self.outbox.steps = point
