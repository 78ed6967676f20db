"""A FIFO of Zenoh samples read by one thread, with timeouts.

The main loop of the server and of each node reads with ``FifoChannel.recv()`` in its
own thread: measured here, that is about a quarter faster per macro step than a
callback handing samples to a ``queue.Queue``. ``recv()`` has no timeout, so a watchdog
thread puts a session-local wake sample on the same key space when a deadline passes;
other threads hand events to the loop the same way (:meth:`inject`), so the loop
has exactly one place to wait.

Before blocking, ``recv`` polls the channel a few times, yielding the CPU between polls:
a sample that comes while it polls is taken without the reading thread going to sleep
and being woken again, which on a small machine costs more than the rest of a
macro step's Python. The number of polls adapts: it doubles when polling caught a
sample and halves when the thread had to block, so a node that waits long for each
release (many nodes, slow peers, real-time pacing) soon polls only a few times.
"""

from __future__ import annotations

import os
import threading
import time

import zenoh

_WAKE = b"\x00wake"
# Each poll is a try_recv and a sched_yield, about 1–2 µs when nothing else runs.
# Measured with benchmarks/barrier.py (medians of three interleaved runs, 2 cores):
# 8/400 gave +30 % steps/s at N = 2, +23 % at N = 4 and no loss at N = 16, where a
# fixed 400 polls per wait lost half the rate to polling.
_POLLS_MIN = 8
_POLLS_MAX = 400


class Inbox:
    """Samples for ``key_expr`` in arrival order; ``recv(timeout)`` returns None on timeout."""

    def __init__(self, session: zenoh.Session, key_expr: str, local_key: str, capacity: int = 8192):
        # local_key must match key_expr; it carries wake-ups and injected events.
        self._session = session
        self._local_key = local_key
        self._sub = session.declare_subscriber(key_expr, zenoh.handlers.FifoChannel(capacity))
        self._deadline: float | None = None
        self._last_wake = 0.0
        self._polls = _POLLS_MIN
        self._closed = threading.Event()
        self._watchdog = threading.Thread(target=self._watch, name="inbox-watchdog", daemon=True)
        self._watchdog.start()

    def _watch(self) -> None:
        # Besides deadlines, a long wait is woken every quarter second so that the
        # reading thread returns to Python and a pending Ctrl-C is raised there.
        while not self._closed.wait(0.01):
            deadline = self._deadline
            now = time.monotonic()
            if deadline is not None and (now >= deadline or now - self._last_wake >= 0.25):
                self._last_wake = now
                self.inject(_WAKE)

    @property
    def polls(self) -> int:
        """How many times the next ``recv`` polls the channel before it blocks."""
        return self._polls

    def inject(self, payload: bytes) -> None:
        """Hand a payload to the reading thread, behind everything already queued."""
        self._session.put(self._local_key, payload, allowed_destination=zenoh.Locality.SESSION_LOCAL,
                          congestion_control=zenoh.CongestionControl.BLOCK)

    def recv(self, timeout: float) -> tuple[str, bytes] | None:
        """The next sample as (key, payload), or None once ``timeout`` seconds pass."""
        now = time.monotonic()
        deadline = now + timeout
        self._last_wake = now
        self._deadline = deadline
        try:
            while True:
                sample = self._next()
                payload = sample.payload.to_bytes()
                if payload == _WAKE:
                    if time.monotonic() >= deadline:
                        return None
                    continue  # a wake-up meant for an earlier recv
                return str(sample.key_expr), payload
        finally:
            self._deadline = None

    def _next(self) -> zenoh.Sample:
        for _ in range(self._polls):
            sample = self._sub.try_recv()
            if sample is not None:
                self._polls = min(_POLLS_MAX, 2 * self._polls)
                return sample
            os.sched_yield()
        self._polls = max(_POLLS_MIN, self._polls // 2)
        return self._sub.recv()

    def close(self) -> None:
        self._closed.set()
        self._watchdog.join(timeout=1.0)
        try:
            self._sub.undeclare()
        except Exception:  # the session may already be closed
            pass
