"""A FIFO of Zenoh samples read by one thread, with timeouts.

The main loop of the server and of each node reads with ``FifoChannel.recv()`` in its
own thread: measured here, that is about a quarter faster per macro step than a
callback handing samples to a ``queue.Queue``. ``recv()`` has no timeout, so a watchdog
thread puts a session-local wake sample on the same key space when a deadline passes;
other threads hand events to the loop the same way (:meth:`inject`), so the loop
has exactly one place to wait.

With ``poll=True`` (the project's ``waitStrategy``), ``recv`` polls the channel before it
blocks, yielding the CPU between polls: a sample that comes while it polls is taken
without the reading thread going to sleep and being woken again, which on a small
machine costs more than the rest of a macro step's Python. The number of polls adapts:
it doubles when polling caught a sample and halves when the thread had to block, down
to none, with a short probe every so often; so a process that waits long for each frame
(slow peers, real-time pacing) soon stops polling. Polling also ends after a millisecond,
however many polls are left: on a loaded machine each yield may give the core away for
long, and unbounded polling would then never block.

Injected payloads come back under the key :data:`LOCAL`, which no Zenoh sample can have.
They travel as session-local puts on ``local_key`` prefixed with a secret drawn per inbox:
a put never leaves its session, so no peer can learn the secret, and a peer that writes on
``local_key`` itself (it may be an ordinary key, the nodes' ``down``) is delivered as the
network sample it is, never as a liveliness change or a wake-up.

:attr:`Inbox.waits` counts how each ``recv`` got its sample, so a run can say whether
polling paid: ``queued`` (already there), ``polled`` (caught while polling), ``slept``
(the thread blocked; a blocking Inbox counts every wait here, queued or not). Wake-ups and
injected events count like frames; in a busy run they are a handful.
"""

from __future__ import annotations

import os
import threading
import time

import zenoh

LOCAL = ""  # the key recv gives injected payloads (Zenoh keys are never empty)
_WAKE = b"\x00wake"
_SECRET_LEN = 16
# A poll is a sched_yield and a try_recv: 1–2 µs when no other process is runnable, a
# hand-over of the core to one that is. Measured with benchmarks/barrier.py on 2 cores
# (medians of interleaved runs): +20–50 % steps/s at N = 2, +25 % at N = 4, a sixth lost
# at N = 8 and a fifth at N = 16 (hence config.polls_before_blocking); a fixed minimum of
# 8 polls per wait, without probing, lost more at N = 16.
_TICK = 0.25  # the longest the reading thread stays out of Python (Ctrl-C)
_PROBE = 8
_PROBE_EVERY = 16
_POLLS_MAX = 400
# Polling pays while it is shorter than a sleep and wake-up (tens of µs). On a loaded
# machine one sched_yield can hand the core away for milliseconds, and 400 of them then
# cover any wait: the reader would never block, and never learn that its peers are slow.
_POLL_BUDGET_S = 0.001


class Inbox:
    """Samples for ``key_expr`` in arrival order; ``recv(timeout)`` returns None on timeout."""

    def __init__(self, session: zenoh.Session, key_expr: str, local_key: str, capacity: int = 8192,
                 poll: bool = False):
        # local_key must match key_expr; it carries wake-ups and injected events.
        self._session = session
        self._local_key = local_key
        self._secret = os.urandom(_SECRET_LEN)
        self._wake = self._secret + _WAKE
        self._sub = session.declare_subscriber(key_expr, zenoh.handlers.FifoChannel(capacity))
        self._deadline: float | None = None
        self._last_wake = 0.0
        self._poll = poll
        self._polls = _PROBE if poll else 0
        self._poll_budget_s = _POLL_BUDGET_S
        self._idle_waits = 0
        self._waits = {"queued": 0, "polled": 0, "slept": 0}
        self._closed = False
        self._kick = threading.Event()  # a recv with a deadline before the watchdog's next wake, or close
        self._watch_until = 0.0  # when the watchdog next wakes by itself
        self._watchdog = threading.Thread(target=self._watch, name="inbox-watchdog", daemon=True)
        self._watchdog.start()

    def _watch(self) -> None:
        # Besides deadlines, a long wait is woken every quarter second so that the
        # reading thread returns to Python and a pending Ctrl-C is raised there. The
        # watchdog sleeps until the earlier of the two rather than polling: with many
        # processes on few cores, a 10 ms poll in each cost a fifth of the barrier's rate
        # at 16 nodes. _watch_until is published before the deadline is read, so a recv
        # that sets an earlier deadline meanwhile sees it and kicks (see recv).
        while not self._closed:
            now = time.monotonic()
            self._watch_until = now + _TICK
            deadline = self._deadline
            if deadline is not None and (now >= deadline or now - self._last_wake >= _TICK):
                self._last_wake = now
                self._put_local(self._wake)
            until = now + _TICK if deadline is None else min(deadline, self._last_wake + _TICK)
            if until <= now:  # woken for a deadline already served: the next recv kicks
                until = now + _TICK
            self._watch_until = until
            self._kick.wait(until - time.monotonic())
            self._kick.clear()

    @property
    def waits(self) -> dict[str, int]:
        """How the samples so far were had: ``queued``, ``polled`` or ``slept`` (see the module doc)."""
        return dict(self._waits)

    @property
    def polls(self) -> int:
        """How many times the next ``recv`` polls the channel before it blocks."""
        return self._polls

    def inject(self, payload: bytes) -> None:
        """Hand a payload to the reading thread, behind everything already queued; ``recv``
        returns it under the key :data:`LOCAL`.

        Once the session is closing there is no reader left: the payload is dropped rather
        than raising in whichever callback or thread injected it.
        """
        self._put_local(self._secret + payload)

    def _put_local(self, payload: bytes) -> None:
        try:
            self._session.put(self._local_key, payload, allowed_destination=zenoh.Locality.SESSION_LOCAL,
                              congestion_control=zenoh.CongestionControl.BLOCK)
        except zenoh.ZError:
            pass

    def recv(self, timeout: float) -> tuple[str, bytes] | None:
        """The next sample as (key, payload), or None once ``timeout`` seconds pass (zero or
        less: None unless a sample is there or comes before the watchdog's wake-up, which is
        sent at once); an injected payload comes as (LOCAL, payload)."""
        now = time.monotonic()
        deadline = now + timeout
        self._last_wake = now
        self._deadline = deadline
        if deadline < self._watch_until:
            self._kick.set()
        try:
            while True:
                if self._poll:
                    sample = self._polled()
                else:  # one call less for every frame of a blocking run
                    self._waits["slept"] += 1
                    sample = self._sub.recv()
                payload = sample.payload.to_bytes()
                key = str(sample.key_expr)
                if key != self._local_key or payload[:_SECRET_LEN] != self._secret:
                    return key, payload
                if payload == self._wake:
                    if time.monotonic() >= deadline:
                        return None
                    continue  # a wake-up meant for an earlier recv
                return LOCAL, payload[_SECRET_LEN:]
        finally:
            self._deadline = None

    def _polled(self) -> zenoh.Sample:
        """The next sample, the channel polled before the thread blocks (see the module's text)."""
        waits = self._waits
        sample = self._sub.try_recv()
        if sample is not None:  # already queued: says nothing about polling
            waits["queued"] += 1
            return sample
        polls = self._polls
        if polls == 0:
            self._idle_waits += 1
            if self._idle_waits % _PROBE_EVERY == 0:
                polls = _PROBE
        until = time.perf_counter() + self._poll_budget_s
        for _ in range(polls):
            os.sched_yield()
            sample = self._sub.try_recv()
            if sample is not None:
                self._polls = min(_POLLS_MAX, max(_PROBE, 2 * polls))
                waits["polled"] += 1
                return sample
            if time.perf_counter() > until:
                break
        self._polls = polls // 2 if polls > _PROBE else 0
        waits["slept"] += 1
        return self._sub.recv()

    def close(self) -> None:
        """Stop the watchdog thread and undeclare the subscriber (a session already closed is let
        go)."""
        self._closed = True
        self._kick.set()
        self._watchdog.join(timeout=1.0)
        try:
            self._sub.undeclare()
        except Exception:  # the session may already be closed
            pass
