"""Event localisation around any algorithm: a step whose end satisfies a guard that did not
hold at its start is taken again shorter, by bisection, until the crossing lies within
eventTolerance of its end (the next point is there)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from hycosim.core.schema import CoSimulation
from hycosim.master import plans
from hycosim.master.algorithms.interface import Barrier, Coupling, MasterAlgorithm, Said, StepRequest, StepTaken
from hycosim.master.localisation import bisect_crossing


class Localised(MasterAlgorithm):
    """``inner`` takes each step; the retakes that locate a crossing go through ``coupling``
    (one take each)."""

    def __init__(self, inner: MasterAlgorithm, coupling: Coupling, cosim: CoSimulation):
        self.inner, self.coupling, self.cosim = inner, coupling, cosim
        self.tolerance = cosim.eventTolerance

    def plan(self, said: Said, barrier: Barrier) -> MasterAlgorithm:
        plan = plans.localisation(self.cosim, said)
        barrier.meta["event_localisation"] = plan.words
        inner = self.inner.plan(said, barrier)
        if not plan.on:
            return inner
        self.inner = inner
        return self

    def step(self, barrier: Barrier, request: StepRequest) -> StepTaken:
        watched = barrier.guard_pending()  # a guard that holds at the step's start was not crossed in it
        taken = self.inner.step(barrier, request)
        tol = self.tolerance
        if watched or not barrier.guard_pending() or taken.h <= tol:
            return taken
        k, t, mode = request.k, request.t, request.mode

        def take(length: float) -> bool:
            barrier.rollback(k, t)
            taken.arrivals, taken.wait = self.coupling.take(barrier, k, t, length, mode)
            return barrier.guard_pending()

        at = bisect_crossing(taken.h, tol, take)
        taken.h, taken.localised = at.hi, {"retries": at.tries, "window": [t + at.lo, t + at.hi]}
        return taken

    def step_length(self) -> float | None:
        return self.inner.step_length()

    def startup_steps(self) -> int:
        return self.inner.startup_steps()

    def frames_only(self) -> str:
        return self.inner.frames_only()

    def checkpoint(self) -> dict[str, Any]:
        return self.inner.checkpoint()

    def restore(self, kept: Mapping[str, Any], barrier: Barrier, what: str) -> None:
        self.inner.restore(kept, barrier, what)
