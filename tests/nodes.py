"""Node implementations used only by tests (loaded as ``tests.nodes:Class``)."""

from __future__ import annotations

from typing import Any

from clients.node import Node, NodeContext


class Text(Node):
    """Every output is a string of ``size`` characters (parameter); inputs are ignored."""

    def setup(self, ctx: NodeContext) -> None:
        self.size = int(ctx.parameter("size", 10))
        self.ports = [p.name for p in ctx.outputs]
        self.k = 0

    def outputs(self) -> dict[str, Any]:
        return {port: (f"{self.k}:" + "x" * self.size)[: self.size] for port in self.ports}

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        self.k += 1


class Clock(Node):
    """``y`` = the time reached; a node that cannot save its state (no rollback, no checkpoints)."""

    OUTPUTS = frozenset({"y"})

    def setup(self, ctx: NodeContext) -> None:
        self.t = ctx.start_time

    def outputs(self) -> dict[str, Any]:
        return {"y": self.t}

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        self.t = t + h
