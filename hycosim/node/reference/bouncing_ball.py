"""A bouncing ball: exact free flight under gravity, impacts located inside the step.

Free flight h(t) = h0 + v0·t − g·t²/2 is integrated in closed form; an impact with the
floor (h = 0 while falling) is found by solving that quadratic, the velocity is
reversed and scaled by the restitution ``e``, and flight resumes within the same macro
step. ``impacts`` counts impacts, so a guard such as ``ball.impacts >= 1`` turns the first
one into a co-simulation event. Driven, the ball takes ``h_in`` and ``v_in``.
"""

from __future__ import annotations

import math
from typing import Any

from hycosim.node import parameters as check
from hycosim.node.interface import Node, NodeContext, pack_state, unpack_state


def fall(h0: float, v0: float, g: float, e: float, duration: float) -> tuple[float, float, int]:
    """Height, velocity and number of impacts after ``duration`` seconds of flight."""
    impacts = 0
    left = duration
    h, v = h0, v0
    while left > 0:
        if h <= 0 and v <= 1e-9:  # resting on the floor
            return 0.0, 0.0, impacts
        # Time until h reaches 0 on the way down: largest root of h + v·s − g·s²/2 = 0.
        disc = v * v + 2 * g * h
        s = (v + math.sqrt(max(disc, 0.0))) / g
        if s > left:
            h, v = h + v * left - 0.5 * g * left * left, v - g * left
            break
        v_impact = v - g * s
        left -= s
        h, v = 0.0, -e * v_impact
        impacts += 1
    return h, v, impacts


class BouncingBall(Node):
    """Parameters: ``h0`` (1.0 m), ``v0`` (0.0 m/s), ``g`` (9.81), ``e`` restitution (0.8)."""

    PARAMETERS = frozenset({"h0", "v0", "g", "e"})
    INPUTS = frozenset({"h_in", "v_in"})
    OUTPUTS = frozenset({"h", "v", "impacts"})

    @classmethod
    def parameter_problems(cls, parameters: dict[str, Any]) -> list[str]:
        return check.problems(check.number(parameters, "h0", at_least=0.0, at_most=1e6),
                              check.number(parameters, "v0", at_least=-1e4, at_most=1e4),
                              check.number(parameters, "g", above=0.0, at_most=1e3),
                              check.number(parameters, "e", at_least=0.0, at_most=1.0))

    def setup(self, ctx: NodeContext) -> None:
        self.h = float(ctx.parameter("h0", 1.0))
        self.v = float(ctx.parameter("v0", 0.0))
        self.g = float(ctx.parameter("g", 9.81))
        self.e = float(ctx.parameter("e", 0.8))
        self.impacts = 0
        self.driven = False

    def outputs(self) -> dict[str, Any]:
        return {"h": self.h, "v": self.v, "impacts": self.impacts}

    def set_mode(self, mode: str, driven: bool) -> None:
        self.driven = driven

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        if self.driven:
            self.h = float(inputs["h_in"])
            self.v = float(inputs.get("v_in", 0.0))
            return
        self.h, self.v, n = fall(self.h, self.v, self.g, self.e, h)
        self.impacts += n

    @property
    def can_rollback(self) -> bool:
        return True

    def get_state(self) -> bytes:
        return pack_state({"h": self.h, "v": self.v, "impacts": self.impacts, "driven": self.driven})

    def set_state(self, state: bytes) -> None:
        s = unpack_state(state, {"h", "v", "impacts", "driven"})
        self.h, self.v, self.impacts, self.driven = float(s["h"]), float(s["v"]), int(s["impacts"]), bool(s["driven"])
