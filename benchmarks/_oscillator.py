"""The accuracy benchmark's coupled oscillator, split in two nodes (force–displacement coupling).

Mass 1 (spring k1 to the wall) takes the coupling force F and gives its displacement x;
mass 2 (spring k2 to the wall, and the coupling spring kc to mass 1) takes mass 1's
displacement and gives its own and the force F = kc·(x2 − x1) it puts on mass 1. Each
integrates its own ODE finely (RK4, ``substeps`` per macro step) on inputs held over the step,
so what the benchmark measures is the coupling's error, not the nodes'.
"""

from __future__ import annotations

from clients.node import Node, NodeContext


def _rk4(f, y: list[float], h: float, n: int) -> list[float]:
    dt = h / n
    for _ in range(n):
        k1 = f(y)
        k2 = f([a + 0.5 * dt * b for a, b in zip(y, k1)])
        k3 = f([a + 0.5 * dt * b for a, b in zip(y, k2)])
        k4 = f([a + dt * b for a, b in zip(y, k3)])
        y = [a + dt / 6.0 * (b + 2 * c + 2 * d + e) for a, b, c, d, e in zip(y, k1, k2, k3, k4)]
    return y


class Mass1(Node):
    def setup(self, ctx: NodeContext) -> None:
        self.m, self.k = ctx.parameter("m", 1.0), ctx.parameter("k", 10.0)
        self.n = int(ctx.parameter("substeps", 20))
        self.y = [ctx.parameter("x0", 0.1), ctx.parameter("v0", 0.0)]

    def outputs(self) -> dict:
        return {"x": self.y[0], "v": self.y[1]}

    def step(self, t: float, h: float, inputs: dict) -> None:
        F = inputs["F"]
        self.y = _rk4(lambda s: [s[1], (-self.k * s[0] + F) / self.m], self.y, h, self.n)

    def get_state(self):
        return list(self.y)

    def set_state(self, state) -> None:
        self.y = list(state)


class Mass2(Node):
    def setup(self, ctx: NodeContext) -> None:
        self.m, self.k, self.kc = ctx.parameter("m", 1.0), ctx.parameter("k", 10.0), ctx.parameter("kc", 100.0)
        self.n = int(ctx.parameter("substeps", 20))
        self.y = [ctx.parameter("x0", 0.0), ctx.parameter("v0", 0.0)]
        self.x1 = ctx.parameter("x1_0", 0.1)

    def outputs(self) -> dict:
        return {"x": self.y[0], "v": self.y[1], "F": self.kc * (self.y[0] - self.x1)}

    def step(self, t: float, h: float, inputs: dict) -> None:
        self.x1 = x1 = inputs["x1"]
        self.y = _rk4(lambda s: [s[1], (-self.k * s[0] - self.kc * (s[0] - x1)) / self.m], self.y, h, self.n)

    def get_state(self):
        return [*self.y, self.x1]

    def set_state(self, state) -> None:
        *self.y, self.x1 = state
