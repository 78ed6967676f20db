"""y = a + b·t: a clock, or a hand moving at constant speed."""

from __future__ import annotations

from typing import Any

from hycosim.node import parameters as check
from hycosim.node.interface import Node, NodeContext, pack_state, unpack_state


class Ramp(Node):
    """Parameters ``a`` (0.0) and ``b`` (1.0); outputs ``y`` and its rate ``v`` = b."""

    PARAMETERS = frozenset({"a", "b"})
    INPUTS = frozenset()
    OUTPUTS = frozenset({"y", "v"})

    @classmethod
    def parameter_problems(cls, parameters: dict[str, Any]) -> list[str]:
        return check.problems(check.number(parameters, "a"), check.number(parameters, "b"))

    def setup(self, ctx: NodeContext) -> None:
        self.a = float(ctx.parameter("a", 0.0))
        self.b = float(ctx.parameter("b", 1.0))
        self.t = ctx.start_time

    def outputs(self) -> dict[str, Any]:
        return {"y": self.a + self.b * self.t, "v": self.b}

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        self.t = t + h

    @property
    def can_rollback(self) -> bool:
        return True

    def get_state(self) -> bytes:
        return pack_state({"t": self.t})

    def set_state(self, state: bytes) -> None:
        s = unpack_state(state, {"t"})
        self.t = float(s["t"])
