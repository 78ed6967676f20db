"""An asynchronous source sampling y = a + b·t at its own rate (a stand-in for a sensor)."""

from __future__ import annotations

import math
from typing import Any

from hycosim.node import parameters as check
from hycosim.node.interface import AsyncSource, NodeContext


class RampSource(AsyncSource):
    """Parameters ``a`` (0.0), ``b`` (1.0); samples at the node's ``rate`` (30 Hz) from t0."""

    PARAMETERS = frozenset({"a", "b", "rate"})
    OUTPUTS = frozenset({"y"})

    @classmethod
    def parameter_problems(cls, parameters: dict[str, Any]) -> list[str]:
        return check.problems(check.number(parameters, "a"), check.number(parameters, "b"),
                              check.number(parameters, "rate", above=0.0, at_most=1e5))  # samples a second

    def setup(self, ctx: NodeContext) -> None:
        self.a = float(ctx.parameter("a", 0.0))
        self.b = float(ctx.parameter("b", 1.0))
        self.rate = float(ctx.parameter("rate", 30.0))
        self.t0 = ctx.start_time
        self.next_index = 0

    def samples_until(self, t: float) -> list[tuple[float, dict[str, Any]]]:
        last = math.floor((t - self.t0) * self.rate + 1e-9)
        out = []
        while self.next_index <= last:
            ts = self.t0 + self.next_index / self.rate
            out.append((ts, {"y": self.a + self.b * ts}))
            self.next_index += 1
        return out
