"""A pythonfmu3 (FMI 3.0) model for the FMU-node tests: y = k·u + b."""

from pythonfmu3 import Fmi3Causality, Fmi3Slave, Fmi3Variability, Float64


class GainModel3(Fmi3Slave):
    description = "y = k*u + b, FMI 3.0 (hycosim test model)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.y = 1.0
        self.k = 0.5
        self.b = 1.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous))
        self.register_variable(Float64("u", causality=Fmi3Causality.input, start=0.0))
        self.register_variable(Float64("y", causality=Fmi3Causality.output))
        self.register_variable(Float64("k", causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable, start=0.5))
        self.register_variable(Float64("b", causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable, start=1.0))

    def do_step(self, current_time, step_size):
        self.y = self.k * self.u + self.b
        return True
