"""Bringing asynchronous samples (a camera, a real robot) to macro-step points.

A source publishes timestamped samples at its own rate. At a macro-step point T the
server uses the newest sample taken at or before T (zero-order hold), or extrapolates
linearly from the newest two, per link, and records the age T − t_sample of what it used.
A sample stamped after T (a paced run that fell behind the wall clock its source lives
on) waits until the co-simulation reaches its time, as if it were not there yet; only
when every kept sample is newer than T is the oldest of them used.
"""

from __future__ import annotations

from bisect import bisect_right
from collections import deque
from typing import Any

KEEP = 64  # samples per source: at 60 Hz, a run may fall a second behind its source


class SampleHistory:
    """The recent samples of one asynchronous node, oldest first."""

    def __init__(self, starts: list[Any]):
        self._starts = starts
        self._samples: deque[tuple[float, list[Any]]] = deque(maxlen=KEEP)
        self.received = 0

    def add(self, t: float, values: list[Any]) -> bool:
        """Keep a sample; samples not newer than the newest are ignored (returns False)."""
        if self._samples and t <= self._samples[-1][0]:
            return False
        self._samples.append((t, values))
        self.received += 1
        return True

    def snapshot(self) -> dict[str, Any]:
        """The kept samples and the count received (for a checkpoint)."""
        return {"samples": [[t, list(v)] for t, v in self._samples], "received": self.received}

    def restore(self, snap: dict[str, Any]) -> None:
        """Back to what :meth:`snapshot` gave."""
        self._samples.clear()
        self._samples.extend((float(t), list(v)) for t, v in snap["samples"])
        self.received = int(snap["received"])

    def _newest_index(self, t: float) -> int:
        """Index of the newest sample taken at or before t (0 if all are newer)."""
        if self._samples[-1][0] <= t + 1e-12:
            return len(self._samples) - 1  # the usual case: nothing from ahead of t
        return max(bisect_right(self._samples, t + 1e-12, key=lambda s: s[0]) - 1, 0)

    def at(self, t: float) -> tuple[float, list[Any]] | None:
        """The sample held at time t (None before the first)."""
        if not self._samples:
            return None
        return self._samples[self._newest_index(t)]

    def value_at(self, index: int, t: float, method: str) -> tuple[Any, float | None]:
        """The port's value brought to time t, and the age of the newest sample used."""
        if not self._samples:
            return self._starts[index], None
        i = self._newest_index(t)
        t1, v1 = self._samples[i]
        age = t - t1
        if method == "linear" and i > 0:
            t0, v0 = self._samples[i - 1]
            slope = (v1[index] - v0[index]) / (t1 - t0)
            return v1[index] + slope * (t - t1), age
        return v1[index], age
