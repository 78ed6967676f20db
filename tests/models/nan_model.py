"""A model that diverges: its output turns NaN at t = 0.1 s, as an unstable integrator's does."""

from hycosim.node.interface import Node


class Diverging(Node):
    OUTPUTS = frozenset({"y"})

    def setup(self, ctx):
        self.t = ctx.start_time

    def outputs(self):
        return {"y": float("nan") if self.t >= 0.1 - 1e-9 else self.t}

    def step(self, t, h, inputs):
        self.t = t + h
