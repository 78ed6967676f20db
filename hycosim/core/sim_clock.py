"""Simulated time against the clock on the wall, for real-time runs."""

from __future__ import annotations

import time


class RealTimeClock:
    """Simulated time on this host's monotonic clock: t0 at ``wall0``, ``factor`` wall seconds
    per simulated second.

    The run's epoch comes as a wall-clock time (the server's, in its START frame: the only
    clock that hosts share). It is moved onto the monotonic clock once, here, so that a later
    step of the wall clock (NTP setting it right, someone setting the date) neither stalls
    the run for the length of the step nor rushes it.
    """

    def __init__(self, t0: float, wall0: float, factor: float):
        self.t0 = t0
        self.factor = factor
        self._mono0 = time.monotonic() - (time.time() - wall0)

    def now(self) -> float:
        """The simulated time it is now."""
        return self.t0 + (time.monotonic() - self._mono0) / self.factor

    def seconds_until(self, t: float) -> float:
        """Wall seconds until simulated time ``t`` is due (negative once it has passed)."""
        return self._mono0 + (t - self.t0) * self.factor - time.monotonic()
