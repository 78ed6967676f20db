"""One mass of the accuracy benchmark's oscillators, as a pythonfmu model (built into an FMU by
benchmarks/accuracy.py, one FMU for every mass of every reference problem).

The mass m hangs on a spring k and a damper c to the wall. It is coupled to its neighbours in
one of two ways (force–displacement coupling):

* it takes a force ``F`` from outside (the neighbour computes it) and gives its displacement;
* or it holds the coupling spring itself: it takes the neighbour's displacement ``xl`` (spring
  ``kl``, the neighbour on its left) or ``xr`` (spring ``kr``, on its right) and gives back the
  force that spring puts on the neighbour, ``Fl = kl·(x − xl)`` or ``Fr = kr·(x − xr)``.

A spring constant of 0 leaves that coupling out. The mass may be struck by a half-sine pulse
(the error-controlled step's sharp transient). It integrates its own ODE finely (RK4, at least
``substeps`` per step and at most ``max_dt`` long) on inputs held over the step, so that the
error the benchmark measures is the coupling's. Its state (registered variables) can be saved
and restored: the coordinator rolls it back for iterative coupling and the controlled step.
"""

import math

from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real


class Mass(Fmi2Slave):
    description = "a mass on a spring and damper, coupled by force or by displacement"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.m, self.k, self.c = 1.0, 10.0, 0.0
        self.kl = self.kr = 0.0
        self.pulse_at, self.pulse_width, self.pulse = 0.0, 1.0, 0.0
        self.substeps, self.max_dt = 20.0, 1e-4
        self.x, self.v = 0.0, 0.0
        self.F = self.xl = self.xr = 0.0
        for name in ("m", "k", "c", "kl", "kr", "pulse_at", "pulse_width", "pulse", "substeps", "max_dt"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        for name in ("F", "xl", "xr"):
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        # x and v are the state and outputs, set as start values (x0 and v0 of the Python nodes).
        self.register_variable(Real("x", causality=Fmi2Causality.output, initial=Fmi2Initial.exact))
        self.register_variable(Real("v", causality=Fmi2Causality.output, initial=Fmi2Initial.exact))
        self.register_variable(Real("Fl", causality=Fmi2Causality.output, initial=Fmi2Initial.exact,
                                    getter=lambda: self.kl * (self.x - self.xl)))
        self.register_variable(Real("Fr", causality=Fmi2Causality.output, initial=Fmi2Initial.exact,
                                    getter=lambda: self.kr * (self.x - self.xr)))

    def _force(self, s, x, v):
        kick = 0.0
        if self.pulse and self.pulse_at <= s <= self.pulse_at + self.pulse_width:
            kick = self.pulse * math.sin(math.pi * (s - self.pulse_at) / self.pulse_width)
        return (-self.k * x - self.c * v + self.F + kick - self.kl * (x - self.xl) - self.kr * (x - self.xr)) / self.m

    def do_step(self, current_time, step_size):
        n = max(int(self.substeps), math.ceil(step_size / self.max_dt))
        dt = step_size / n
        x, v = self.x, self.v
        for i in range(n):
            s = current_time + i * dt
            a1 = self._force(s, x, v)
            x2, v2 = x + 0.5 * dt * v, v + 0.5 * dt * a1
            a2 = self._force(s + 0.5 * dt, x2, v2)
            x3, v3 = x + 0.5 * dt * v2, v + 0.5 * dt * a2
            a3 = self._force(s + 0.5 * dt, x3, v3)
            x4, v4 = x + dt * v3, v + dt * a3
            a4 = self._force(s + dt, x4, v4)
            x, v = x + dt / 6 * (v + 2 * v2 + 2 * v3 + v4), v + dt / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        self.x, self.v = x, v
        return True
