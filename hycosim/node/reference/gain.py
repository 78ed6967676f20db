"""y = k·u + b: a static gain, the benchmark ring's workload."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

from hycosim.core.schema import Port, PortType
from hycosim.node import parameters as check
from hycosim.node.interface import Node, NodeContext, pack_state, unpack_state


class Gain(Node):
    """Parameters ``k`` (1.0) and ``b`` (0.0), both tunable during a run; input ``u``, output ``y``. ``work_s`` (0.0)
    spends that much wall time per step, standing in for an expensive model (benchmarks,
    and the report's "who held the barrier").

    Its output at T+H is computed from the input sampled at T, so a chain of gains shows
    the Jacobi scheme's one-step delay per hop exactly.
    """

    PARAMETERS = frozenset({"k", "b", "work_s"})
    INPUTS = frozenset({"u"})
    OUTPUTS = frozenset({"y"})
    FEEDTHROUGH = {"y": frozenset({"u"})}

    @classmethod
    def parameter_problems(cls, parameters: dict[str, Any]) -> list[str]:
        return check.problems(check.number(parameters, "k"), check.number(parameters, "b"),
                              check.number(parameters, "work_s", at_least=0.0))

    def setup(self, ctx: NodeContext) -> None:
        self.k = float(ctx.parameter("k", 1.0))
        self.b = float(ctx.parameter("b", 0.0))
        self.work_s = float(ctx.parameter("work_s", 0.0))
        start = ctx.inputs[0].start_value() if ctx.inputs else 0.0
        self.y = self.k * start + self.b

    def outputs(self) -> dict[str, Any]:
        return {"y": self.y}

    def tunable_values(self) -> dict[str, Any]:
        return {"k": self.k, "b": self.b}

    def set_parameters(self, values: dict[str, Any]) -> None:
        self.k = float(values.get("k", self.k))
        self.b = float(values.get("b", self.b))

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        if self.work_s > 0:
            time.sleep(self.work_s)
        self.y = self.k * inputs["u"] + self.b

    def listed_step(self, inputs: list[str],
                    outputs: list[Port]) -> Callable[[float, float, Sequence[Any]], list[Any]] | None:
        """step() then outputs() on lists, where the ports are the gain's own (input ``u``, and
        output ``y`` a real scalar, its wire value a float) and they are the gain's own too: a
        subclass that changes step() or outputs() is stepped through them. A gain that stands in
        for an expensive model (``work_s``, fixed at setup) steps through them too: its step
        is its sleep, and the benchmark ring's gains then ask nothing of it at every step."""
        if not self.steps_as(Gain) or self.work_s > 0:
            return None
        if inputs != ["u"] or [(p.name, p.type, p.shape) for p in outputs] != [("y", PortType.REAL, None)]:
            return None

        def step(t: float, h: float, values: Sequence[Any]) -> list[Any]:
            self.y = y = self.k * values[0] + self.b
            return [y]
        return step

    @property
    def can_rollback(self) -> bool:
        return True

    def get_state(self) -> bytes:
        return pack_state({"y": self.y})

    def set_state(self, state: bytes) -> None:
        s = unpack_state(state, {"y"})
        self.y = float(s["y"])
