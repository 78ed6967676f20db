"""A pythonfmu3 (FMI 3.0) model whose output follows its input at once: y = 2·u, computed
whenever it is read (a direct feedthrough, also in initialisation mode)."""

from pythonfmu3 import Fmi3Causality, Fmi3Slave, Fmi3Variability, Float64


class Feedthrough3(Fmi3Slave):
    description = "y = 2 u at once, FMI 3.0 (hycosim test model)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous))
        self.register_variable(Float64("u", causality=Fmi3Causality.input, start=0.0))
        self.register_variable(Float64("y", causality=Fmi3Causality.output, getter=lambda: 2.0 * self.u))

    def do_step(self, current_time, step_size):
        return True
