"""A pythonfmu model for the FMU-node tests: y = k·u + b, or y = u while the input ``follow``
is true (a node an event can drive); do_step fails from t >= fail_at."""

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real


class GainModel(Fmi2Slave):
    description = "y = k*u + b (hycosim test model)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.y = 1.0
        self.k = 0.5
        self.b = 1.0
        self.fail_at = 1e9
        self.count = 0
        self.follow = False
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Boolean("follow", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete))
        self.register_variable(Real("y", causality=Fmi2Causality.output, initial=Fmi2Initial.exact))
        self.register_variable(Integer("count", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete, initial=Fmi2Initial.exact))
        self.register_variable(Real("k", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("b", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("fail_at", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))

    def do_step(self, current_time, step_size):
        if current_time >= self.fail_at:
            return False
        self.y = self.u if self.follow else self.k * self.u + self.b
        self.count += 1
        return True
