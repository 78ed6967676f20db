"""The accuracy benchmark's coupled oscillator, split in two nodes (force–displacement coupling).

Mass 1 (spring k1 and damper c to the wall) takes the coupling force F and gives its
displacement x; mass 2 (spring k2 and damper c to the wall, and the coupling spring kc to
mass 1) takes mass 1's displacement and gives its own and the force F = kc·(x2 − x1) it puts
on mass 1. Mass 1 may be struck by a half-sine force pulse (``pulse`` N at ``pulse_at`` s,
lasting ``pulse_width`` s): the sharp transient of the error-controlled step's benchmark. Each
integrates its own ODE finely (RK4, ``substeps`` per macro step) on inputs held over the step,
so what the benchmark measures is the coupling's error, not the nodes'.
"""

from __future__ import annotations

import math

from clients.node import Node, NodeContext


def _rk4(f, y: list[float], t: float, h: float, n: int, max_dt: float) -> list[float]:
    """y' = f(s, y) from t over h, in at least n substeps of at most max_dt (a long controlled
    step is integrated as finely as a short one)."""
    n = max(n, math.ceil(h / max_dt))
    dt = h / n
    for i in range(n):
        s = t + i * dt
        k1 = f(s, y)
        k2 = f(s + 0.5 * dt, [a + 0.5 * dt * b for a, b in zip(y, k1)])
        k3 = f(s + 0.5 * dt, [a + 0.5 * dt * b for a, b in zip(y, k2)])
        k4 = f(s + dt, [a + dt * b for a, b in zip(y, k3)])
        y = [a + dt / 6.0 * (b + 2 * c + 2 * d + e) for a, b, c, d, e in zip(y, k1, k2, k3, k4)]
    return y


def pulse(s: float, at: float, width: float, peak: float) -> float:
    """A half-sine force pulse: ``peak`` newtons at its middle, nothing outside [at, at + width]."""
    return peak * math.sin(math.pi * (s - at) / width) if at <= s <= at + width else 0.0


class Mass1(Node):
    def setup(self, ctx: NodeContext) -> None:
        self.m, self.k, self.c = ctx.parameter("m", 1.0), ctx.parameter("k", 10.0), ctx.parameter("c", 0.0)
        self.n, self.max_dt = int(ctx.parameter("substeps", 20)), ctx.parameter("max_dt", 1e-4)
        self.kick = (ctx.parameter("pulse_at", 0.0), ctx.parameter("pulse_width", 1.0), ctx.parameter("pulse", 0.0))
        self.y = [ctx.parameter("x0", 0.1), ctx.parameter("v0", 0.0)]

    def outputs(self) -> dict:
        return {"x": self.y[0], "v": self.y[1]}

    def step(self, t: float, h: float, inputs: dict) -> None:
        F = inputs["F"]
        self.y = _rk4(lambda s, y: [y[1], (-self.k * y[0] - self.c * y[1] + F + pulse(s, *self.kick)) / self.m],
                      self.y, t, h, self.n, self.max_dt)

    @property
    def can_rollback(self) -> bool:
        return True

    def get_state(self):
        return list(self.y)

    def set_state(self, state) -> None:
        self.y = list(state)


class Mass2(Node):
    FEEDTHROUGH = {"F": frozenset({"x1"})}  # the spring's force reads mass 1's position as it comes

    def setup(self, ctx: NodeContext) -> None:
        self.m, self.k, self.kc = ctx.parameter("m", 1.0), ctx.parameter("k", 10.0), ctx.parameter("kc", 100.0)
        self.c = ctx.parameter("c", 0.0)
        self.n, self.max_dt = int(ctx.parameter("substeps", 20)), ctx.parameter("max_dt", 1e-4)
        self.y = [ctx.parameter("x0", 0.0), ctx.parameter("v0", 0.0)]
        self.x1 = ctx.parameter("x1_0", 0.1)

    def outputs(self) -> dict:
        return {"x": self.y[0], "v": self.y[1], "F": self.kc * (self.y[0] - self.x1)}

    def step(self, t: float, h: float, inputs: dict) -> None:
        self.x1 = x1 = inputs["x1"]
        self.y = _rk4(lambda s, y: [y[1], (-self.k * y[0] - self.c * y[1] - self.kc * (y[0] - x1)) / self.m],
                      self.y, t, h, self.n, self.max_dt)

    @property
    def can_rollback(self) -> bool:
        return True

    def get_state(self):
        return [*self.y, self.x1]

    def set_state(self, state) -> None:
        *self.y, self.x1 = state
