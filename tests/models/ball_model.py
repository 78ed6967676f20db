"""A pythonfmu bouncing ball whose state can be saved and restored (rollback tests)."""

import math

from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real


class BallModel(Fmi2Slave):
    description = "bouncing ball, exact free flight, impacts located inside the step"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.h = 1.0
        self.v = 0.0
        self.g = 9.81
        self.e = 0.8
        self.impacts = 0
        self.register_variable(Real("h", causality=Fmi2Causality.output, initial=Fmi2Initial.exact))
        self.register_variable(Real("v", causality=Fmi2Causality.output, initial=Fmi2Initial.exact))
        self.register_variable(Integer("impacts", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete, initial=Fmi2Initial.exact))
        self.register_variable(Real("g", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Real("e", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))

    def do_step(self, current_time, step_size):
        left = step_size
        while left > 0:
            if self.h <= 0 and self.v <= 1e-9:
                self.h, self.v = 0.0, 0.0
                break
            s = (self.v + math.sqrt(max(self.v * self.v + 2 * self.g * self.h, 0.0))) / self.g
            if s > left:
                self.h, self.v = self.h + self.v * left - 0.5 * self.g * left * left, self.v - self.g * left
                break
            left -= s
            self.h, self.v = 0.0, -self.e * (self.v - self.g * s)
            self.impacts += 1
        return True
