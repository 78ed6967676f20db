"""Bringing asynchronous samples (a camera, a real robot) to macro-step points.

A source publishes timestamped samples at its own rate. At a macro-step point T the
server uses the latest sample (zero-order hold) or extrapolates linearly from the last
two, per link, and records the age T − t_sample of what it used.
"""

from __future__ import annotations

from typing import Any


class SampleHistory:
    """The last two samples of one asynchronous node."""

    def __init__(self, starts: list[Any]):
        self._starts = starts
        self.latest: tuple[float, list[Any]] | None = None
        self.previous: tuple[float, list[Any]] | None = None
        self.received = 0

    def add(self, t: float, values: list[Any]) -> bool:
        """Keep a sample; samples older than the latest are ignored (returns False)."""
        if self.latest is not None and t <= self.latest[0]:
            return False
        self.previous, self.latest = self.latest, (t, values)
        self.received += 1
        return True

    def value_at(self, index: int, t: float, method: str) -> tuple[Any, float | None]:
        """The port's value brought to time t, and the age of the newest sample used."""
        if self.latest is None:
            return self._starts[index], None
        t1, v1 = self.latest
        age = t - t1
        if method == "linear" and self.previous is not None:
            t0, v0 = self.previous
            slope = (v1[index] - v0[index]) / (t1 - t0)
            return v1[index] + slope * (t - t1), age
        return v1[index], age
