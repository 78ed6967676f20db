"""Iterated coupling: each step taken again until the inputs routed from its end settle,
optionally on inputs that follow polynomials over the step (FMI input derivatives)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import structlog

from hycosim.core.schema import Iterate
from hycosim.master import plans
from hycosim.master.algorithms.interface import (Algorithm, AlgorithmError, Barrier, Coupling, Inputs, MasterAlgorithm, Said,
                                                 StepRequest, StepTaken)
from hycosim.master.interpolation import STARTUP_SPLIT, InputTrack
from hycosim.master.retakes import IterationLog, input_change, iterate_step


class Iterated(Algorithm):
    """Take step k with ``coupling``, then again (rolled back) on the inputs its end routes to
    (relaxed), until they change by at most the tolerance or maxIterations is reached. The
    inputs it was last taken on are point k's record."""

    def __init__(self, settings: Iterate, coupling: Coupling):
        self.settings, self.coupling = settings, coupling
        self.log = IterationLog(settings)
        self.track: InputTrack | None = None
        self._startup = 0
        self._logger = structlog.get_logger("server")

    def plan(self, said: Said, barrier: Barrier) -> MasterAlgorithm:
        it = self.settings
        plan = plans.iteration(it, said, {n: bool(ports) for n, ports in barrier.input_labels.items()})
        barrier.meta["iteration"] = plan.words
        if not plan.on:
            self._logger.warning("no iterative coupling", why=plan.why)
            return self.coupling
        if plan.interpolated:
            self.track = InputTrack(it.interpolate, list(plan.interpolated))
            self._startup = (it.interpolate - 1) * STARTUP_SPLIT
        elif it.interpolate > 0:
            self._logger.warning("no interpolated inputs", nodes=list(plan.holding))
        return self

    def startup_steps(self) -> int:
        return self._startup

    def frames_only(self) -> str:
        return "interpolated inputs" if self.track is not None else ""

    def checkpoint(self) -> dict[str, Any]:
        return {"track": self.track.snapshot()} if self.track is not None else {}

    def restore(self, kept: Mapping[str, Any], barrier: Barrier, what: str) -> None:
        """The interpolated inputs' points before the checkpoint, so that the steps from it are
        taken on the polynomials they were taken on before."""
        if self.track is None:
            return
        try:
            self.track.restore(kept.get("track"))
        except ValueError as exc:
            raise ValueError(f"{what}: {exc}") from None
        ours = barrier.inputs
        if any(set(values) != set(ours) or any(len(values[n]) != len(ours[n]) for n in ours)
               for _, values in self.track.snapshot()["points"]):
            raise ValueError(f"{what} does not fit the project: its interpolated inputs differ")

    def step(self, barrier: Barrier, request: StepRequest) -> StepTaken:
        try:
            return self._iterate(barrier, request)
        finally:
            request.record()  # also when the step failed: point k stands

    def _iterate(self, barrier: Barrier, request: StepRequest) -> StepTaken:
        k, t, h, mode = request.k, request.t, request.h, request.mode
        it, track = self.settings, self.track
        start: Inputs = {}
        if track is not None:
            # The routed inputs are point k's; the step is taken on its end values (first guessed
            # from the points before), which the interpolating nodes reach along a polynomial.
            track.add(t, mode, barrier.inputs)
            start = track.start()
            barrier.inputs = track.first_guess(t, h)
        arrivals: dict[str, float] = {}
        wait = 0.0

        def moving() -> dict[str, Any]:
            """An interpolating node gets the value at the step's start and the derivatives there; any other the end value."""
            if track is None:
                return {}
            end = barrier.inputs
            inputs = {n: start[n] if n in track.nodes else end[n] for n in end}
            return {"inputs": inputs, "slopes": track.slopes(t, h, end)}

        def change(used: Inputs) -> tuple[Inputs, float, str, float]:
            candidate = barrier.candidate(mode)
            return (candidate, *input_change(candidate, used, barrier.input_labels, it.tolerance))

        def retake(inputs: Inputs) -> None:
            nonlocal arrivals, wait
            barrier.rollback(k, t)
            barrier.inputs = inputs
            arrivals, wait = self.coupling.take(barrier, k, t, h, mode, **moving())

        try:
            arrivals, wait = self.coupling.take(barrier, k, t, h, mode, **moving())
            s = iterate_step(barrier.inputs, change, retake, it)
        finally:
            for n in track.nodes if track is not None else ():  # point k's record: what each had at t
                barrier.inputs[n] = start[n]
        self.log.add(k, t, s.takes, s.change, s.port, s.absolute)
        barrier.meta["iterations"] = self.log.record()  # in the meta however the run ends
        if not s.converged:
            self._logger.warning("step did not converge", step=k, t=t, takes=s.takes, port=s.port, change=s.absolute)
            if it.onFailure == "stop":
                raise AlgorithmError(f"step {k} (t={t:g} s) did not converge in {s.takes} takes: input {s.port} still "
                                 f"changed by {s.absolute:g} (tolerance {it.tolerance:g}·max(1, |value|))")
        return StepTaken(h, arrivals, wait, s.takes)
