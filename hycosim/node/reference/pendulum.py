"""A damped pendulum integrated by RK4 micro-steps inside each macro step.

θ'' = −(g/L)·sin θ − c·θ'. Free, it follows its own dynamics; driven, it takes its angle
and angular velocity from the inputs ``theta_in`` and ``omega_in`` (s_A = g_B(s_B)).
"""

from __future__ import annotations

import math
from typing import Any

from hycosim.node import parameters as check
from hycosim.node.interface import Node, NodeContext, pack_state, unpack_state


class Pendulum(Node):
    """Parameters: ``length`` (1.0 m), ``g`` (9.81), ``damping`` c (0.0 1/s),
    ``theta0`` (rad), ``omega0`` (rad/s), ``micro_steps`` per macro step (10)."""

    PARAMETERS = frozenset({"length", "g", "damping", "theta0", "omega0", "micro_steps"})
    INPUTS = frozenset({"theta_in", "omega_in"})
    # The pivot and the bob in the x–z plane (m): what a dashboard draws of it.
    OUTPUTS = frozenset({"theta", "omega", "pivot_x", "pivot_z", "bob_x", "bob_z"})

    @classmethod
    def parameter_problems(cls, parameters: dict[str, Any]) -> list[str]:
        return check.problems(check.number(parameters, "length", at_least=1e-3, at_most=1e3),
                              check.number(parameters, "g", at_least=-1e3, at_most=1e3),
                              check.number(parameters, "damping", at_least=0.0, at_most=1e3),
                              check.number(parameters, "theta0", at_least=-1e3, at_most=1e3),
                              check.number(parameters, "omega0", at_least=-1e3, at_most=1e3),
                              check.number(parameters, "micro_steps", at_least=1, at_most=1_000_000, whole=True))

    def setup(self, ctx: NodeContext) -> None:
        self.length = float(ctx.parameter("length", 1.0))
        self.g = float(ctx.parameter("g", 9.81))
        self.c = float(ctx.parameter("damping", 0.0))
        self.theta = float(ctx.parameter("theta0", 0.5))
        self.omega = float(ctx.parameter("omega0", 0.0))
        self.micro = int(ctx.parameter("micro_steps", 10))
        self.driven = False

    def _deriv(self, theta: float, omega: float) -> tuple[float, float]:
        return omega, -(self.g / self.length) * math.sin(theta) - self.c * omega

    def outputs(self) -> dict[str, Any]:
        return {"theta": self.theta, "omega": self.omega, "pivot_x": 0.0, "pivot_z": 0.0,
                "bob_x": self.length * math.sin(self.theta), "bob_z": -self.length * math.cos(self.theta)}

    def set_mode(self, mode: str, driven: bool) -> None:
        self.driven = driven

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        if self.driven:
            self.theta = float(inputs["theta_in"])
            self.omega = float(inputs.get("omega_in", 0.0))
            return
        dt = h / self.micro
        th, om = self.theta, self.omega
        for _ in range(self.micro):
            k1 = self._deriv(th, om)
            k2 = self._deriv(th + dt / 2 * k1[0], om + dt / 2 * k1[1])
            k3 = self._deriv(th + dt / 2 * k2[0], om + dt / 2 * k2[1])
            k4 = self._deriv(th + dt * k3[0], om + dt * k3[1])
            th += dt / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            om += dt / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        self.theta, self.omega = th, om

    @property
    def can_rollback(self) -> bool:
        return True

    def get_state(self) -> bytes:
        return pack_state({"theta": self.theta, "omega": self.omega, "driven": self.driven})

    def set_state(self, state: bytes) -> None:
        s = unpack_state(state, {"theta", "omega", "driven"})
        self.theta, self.omega, self.driven = float(s["theta"]), float(s["omega"]), bool(s["driven"])
