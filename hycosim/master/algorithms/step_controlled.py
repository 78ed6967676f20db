"""The error-controlled macro step: each step taken shorter again while its held inputs
changed too much over it; the next step's length follows the error."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import structlog

from hycosim.core.schema import StepControl
from hycosim.master import plans
from hycosim.master.algorithms.interface import (Algorithm, Barrier, Coupling, Inputs, MasterAlgorithm, Said,
                                                 StepRequest, StepTaken)
from hycosim.master.retakes import StepSizer, control_step, input_change


class StepControlled(Algorithm):
    """Steps between minStep and maxStep whose held inputs' error (change × step / 2) stays
    within the tolerance; a step over it is rolled back and taken shorter."""

    def __init__(self, settings: StepControl, step_size: float, coupling: Coupling):
        self.settings, self.step_size, self.coupling = settings, step_size, coupling
        self.sizer = StepSizer.starting(settings, step_size)

    def plan(self, said: Said, barrier: Barrier) -> MasterAlgorithm:
        plan = plans.step_control(self.settings, self.step_size, said)
        barrier.meta["step_control"] = plan.words
        if not plan.on:
            structlog.get_logger("server").warning("no step control", why=plan.why)
            return self.coupling
        return self

    def step_length(self) -> float | None:
        return self.sizer.h

    def checkpoint(self) -> dict[str, Any]:
        return {"h": float(self.sizer.h)}

    def restore(self, kept: Mapping[str, Any], barrier: Barrier, what: str) -> None:
        if "h" not in kept:
            return  # kept by a run that fell back to fixed steps
        h = kept["h"]
        if type(h) is not float or not self.settings.minStep <= h <= self.settings.maxStep:
            raise ValueError(f"{what}: its next step {h!r} is no step between minStep and maxStep")
        self.sizer.h = h

    def step(self, barrier: Barrier, request: StepRequest) -> StepTaken:
        k, t, mode = request.k, request.t, request.mode
        tolerance = self.sizer.settings.tolerance
        used: Inputs = {n: list(v) for n, v in barrier.inputs.items()}
        arrivals, wait = self.coupling.take(barrier, k, t, request.h, mode, meanwhile=request.record)

        def change() -> float:
            return input_change(barrier.candidate(mode), used, barrier.input_labels, tolerance)[0]

        def retake(length: float) -> None:
            nonlocal arrivals, wait
            barrier.rollback(k, t)
            arrivals, wait = self.coupling.take(barrier, k, t, length, mode)

        h, takes = control_step(request.h, change, retake, self.sizer)
        barrier.meta["step_sizes"] = self.sizer.record()  # in the meta however the run ends
        return StepTaken(h, arrivals, wait, takes)
