"""A port's values over time, thinned so that the browser gets a bounded number of points.

A live run may take millions of steps; a plot a thousand pixels wide shows no more than a
few thousand points. A series keeps every ``stride``-th value it is given; when it holds
twice its capacity it drops every other point it holds and doubles the stride, so it always
spans the whole run at an even spacing, in O(capacity) memory.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass
class ThinnedSeries:
    """One port's values over time, at most about twice ``capacity`` points at an even spacing (see the
    module's text)."""

    capacity: int = 1000
    t: list[float] = field(default_factory=list)
    y: list[float] = field(default_factory=list)
    stride: int = 1
    version: int = 0  # changes whenever points already held change (thinned, or undone)
    _seen: int = 0

    def add(self, t: float, y: float) -> None:
        """Append a value (points arrive in time order; a non-finite one is a gap)."""
        undone = False
        while self.t and t < self.t[-1]:  # a step taken again, shorter: what it drew is undone
            self.t.pop()
            self.y.pop()
            undone = True
        if undone:
            self.version += 1
        if self.t and t == self.t[-1]:
            self.y[-1] = y if math.isfinite(y) else math.nan  # the same point again: its last value
            self.version += 1
            return
        self._seen += 1
        if (self._seen - 1) % self.stride and not undone:
            return
        self.t.append(t)
        self.y.append(y if math.isfinite(y) else math.nan)
        if len(self.t) >= 2 * self.capacity:
            self.t, self.y = self.t[::2], self.y[::2]
            self.stride *= 2
            self.version += 1

    def points(self) -> list[list[float | None]]:
        """``[t, y]`` for JSON (a gap as null)."""
        return [list(self.t), [None if math.isnan(v) else v for v in self.y]]

    def since(self, version: int, count: int) -> dict | None:
        """What a page holding ``count`` points of ``version`` lacks: the points after those
        (``from`` = count), or all of them (``from`` = 0) if the held ones changed; None if nothing."""
        if version == self.version and count == len(self.t):
            return None
        start = count if version == self.version and count < len(self.t) else 0
        return {"version": self.version, "from": start, "t": self.t[start:],
                "y": [None if math.isnan(v) else v for v in self.y[start:]]}
