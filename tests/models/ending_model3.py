"""A pythonfmu3 (FMI 3.0) model that ends the simulation: from t >= end_at its doStep asks to
terminate (terminateSimulation), or, with discard true, discards the step without asking."""

from pythonfmu3 import Boolean, Fmi3Causality, Fmi3Slave, Fmi3Variability, Float64
from pythonfmu3.enums import Fmi3Status
from pythonfmu3.fmi3slave import Fmi3StepResult


class EndingModel3(Fmi3Slave):
    description = "x = t until end_at, then terminateSimulation (hycosim test model)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.time = 0.0
        self.x = 0.0
        self.end_at = 1e9
        self.discard = False
        self.register_variable(Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous))
        self.register_variable(Float64("x", causality=Fmi3Causality.output))
        self.register_variable(Float64("end_at", causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable, start=1e9))
        self.register_variable(Boolean("discard", causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable, start=False))

    def do_step(self, current_time, step_size):
        if current_time + step_size > self.end_at + 1e-9:
            if self.discard:
                return Fmi3StepResult(status=Fmi3Status.discard)
            self.x = self.end_at
            return Fmi3StepResult(terminateSimulation=True)
        self.x = current_time + step_size
        return Fmi3StepResult()
