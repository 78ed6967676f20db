"""How many status answers the server builds a second.

Anyone who reaches the server may ask its status queryable (``hycosim status``, dashboards).
An answer is built in Zenoh's thread under the GIL while the barrier waits, about 2 ms at a
fast run's pace, so one peer asking in a loop (some 2,700 questions a second) took a 2-node
ring from 3,000 steps/s to 500. The budget is a token bucket: a steady rate with a burst
above it, far more than the askers a run has (a dashboard asks five times a second). A
question beyond it is answered with a short error at once, built from nothing, and counted.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

ANSWERS_PER_S = 40.0  # eight dashboards at once, and `hycosim status` beside them
BURST = 20


class AnswerBudget:
    """A token bucket of ``per_s`` answers a second, ``burst`` at once; :attr:`refused` counts
    the questions it turned away. Safe from any thread (Zenoh calls from several)."""

    def __init__(self, per_s: float = ANSWERS_PER_S, burst: int = BURST,
                 clock: Callable[[], float] = time.monotonic):
        self.per_s = per_s
        self.burst = burst
        self.refused = 0
        self._clock = clock
        self._tokens = float(burst)
        self._at = clock()
        self._lock = threading.Lock()

    def take(self) -> bool:
        """Whether one more answer may be built now (and, if so, it is taken from the budget)."""
        with self._lock:
            now = self._clock()
            self._tokens = min(float(self.burst), self._tokens + max(0.0, now - self._at) * self.per_s)
            self._at = now
            if self._tokens >= 1.0:
                self._tokens -= 1.0
                return True
            self.refused += 1
            return False
