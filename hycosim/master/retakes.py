"""Steps taken again after a rollback: iterative coupling and the error-controlled macro step.

Both measure one thing: how far the inputs routed from a step's end lie from those the step
was taken on, each port's change in units of ``tolerance``·max(1, |value|) (absolute for
values below 1, relative above, so that a force of 100 N and a position of 1 mm are judged
alike). The worst port's is the step's change.

* Iterative coupling (coSimulation.iterate) takes the step again, every node rolled back, on
  the inputs routed from its end (relaxed) until the change is at most 1: the fixed point of
  an implicit scheme, whose inputs are the step's end values held over it.
* The error-controlled step (coSimulation.stepControl) estimates the error of holding the
  inputs over the step: an input that moved by Δu from one end of the step to the other, held
  at its start value, was wrong by Δu/2 on average, so by Δu·h/2 integrated over the step (for
  a force, the impulse the node missed). A step whose estimate is above its tolerance is taken
  again shorter; otherwise the next one is sized to bring the estimate near the tolerance.
  The estimate grows as h² (Δu as u'·h), so the new step is h·√(safety/estimate). Measured
  (benchmarks/accuracy.py): judged by the change Δu alone, as first built, a long decaying
  tail took long steps that carried most of the error while the ringing after a pulse sat at
  minStep; the integral spends the steps where they pay. The estimate costs nothing on an
  accepted step, where step doubling would take every step three times; it needs a rollback
  only for a rejected one.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Mapping

from hycosim.core.schema import Iterate, StepControl

SAFETY = 0.8  # aim below the tolerance, so that the next step is not rejected
SHRINK_MOST, GROW_MOST = 0.2, 2.0  # a step changes by at most these factors at once


def _is_number(value: Any) -> bool:
    return type(value) in (int, float)  # a bool or bytes is no coupled quantity to measure


def input_change(candidate: Mapping[str, list[Any]], used: Mapping[str, list[Any]],
                 labels: Mapping[str, list[str]], tolerance: float) -> tuple[float, str, float]:
    """The worst port's change from ``used`` to ``candidate`` in tolerances, its label and the
    absolute change (0, "", 0 when no numeric input moved)."""
    worst, where, absolute = 0.0, "", 0.0
    for node, new in candidate.items():
        old = used[node]
        for i, (a, b) in enumerate(zip(old, new)):
            if a == b:
                continue
            if type(a) is list and type(b) is list:  # an array input: element by element
                pairs = [(f"{labels[node][i]}[{j}]", x, y) for j, (x, y) in enumerate(zip(a, b))]
            else:
                pairs = [(labels[node][i], a, b)]
            for label, x, y in pairs:
                if x == y or not (_is_number(x) and _is_number(y)):
                    continue
                d = abs(y - x)
                scaled = d / (tolerance * max(1.0, abs(x), abs(y)))
                if not math.isfinite(scaled):
                    scaled = math.inf  # a non-finite input never converges; the step's node said so
                if scaled > worst:
                    worst, where, absolute = scaled, label, d
    return worst, where, absolute


def relaxed(candidate: Mapping[str, list[Any]], used: Mapping[str, list[Any]], factor: float) -> dict[str, list[Any]]:
    """old + factor·(new − old) for every numeric input; any other takes the new value."""
    if factor == 1.0:
        return {n: list(v) for n, v in candidate.items()}
    out: dict[str, list[Any]] = {}
    for node, new in candidate.items():
        old = used[node]
        out[node] = [_relax(a, b, factor) for a, b in zip(old, new)]
    return out


def _relax(a: Any, b: Any, factor: float) -> Any:
    if type(a) is list and type(b) is list:
        return [_relax(x, y, factor) for x, y in zip(a, b)]
    return a + factor * (b - a) if type(a) is float and _is_number(b) else b


# What a step's end says of the inputs it was taken on (``used``): the inputs routed from its
# end, and their change from ``used`` as input_change measures it (in tolerances, the worst
# port, its absolute change).
Measure = Callable[[dict[str, list[Any]]], tuple[dict[str, list[Any]], float, str, float]]


@dataclass(frozen=True)
class Settled:
    """How an iterated step ended: taken ``takes`` times, the last on ``used``, whose change
    (in tolerances; at most 1 where it converged) was worst at ``port`` by ``absolute``."""

    takes: int
    used: dict[str, list[Any]]
    change: float
    port: str
    absolute: float

    @property
    def converged(self) -> bool:
        """Whether the last take's change was within the tolerances."""
        return self.change <= 1.0


def iterate_step(used: dict[str, list[Any]], measure: Measure, retake: Callable[[dict[str, list[Any]]], None],
                 settings: Iterate) -> Settled:
    """Iterative coupling of one step, already taken once on the inputs ``used``: while the
    inputs routed from its end changed by more than the tolerance and takes are left (at most
    ``settings.maxIterations``, the first included), ``retake`` rolls every node back and takes
    the step again on those inputs relaxed towards the ones it was last taken on."""
    takes = 1
    while True:
        candidate, change, port, absolute = measure(used)
        if change <= 1.0 or takes >= settings.maxIterations:
            return Settled(takes, used, change, port, absolute)
        used = relaxed(candidate, used, settings.relaxation)
        retake(used)
        takes += 1


def control_step(h: float, measure: Callable[[], float], retake: Callable[[float], None],
                 sizer: StepSizer) -> tuple[float, int]:
    """The error-controlled step, already taken once with length ``h``: while ``sizer`` rejects
    it for the change ``measure()`` finds over it (in tolerances), ``retake`` rolls every node
    back and takes it again with the shorter length the sizer gives. Return the length that
    stood and how often the step was taken; the sizer has set the next step to try."""
    takes = 1
    while (shorter := sizer.judge(h, measure())) is not None:
        h = shorter
        retake(h)
        takes += 1
    return h, takes


@dataclass
class IterationLog:
    """What iterative coupling did over a run, for meta.json and the report."""

    settings: Iterate
    steps: int = 0
    takes: int = 0
    most: int = 0
    not_converged: int = 0
    worst: dict[str, Any] = field(default_factory=dict)  # the largest change a step was left with
    _worst_change: float = 0.0

    def add(self, step: int, t: float, takes: int, change: float, port: str, absolute: float) -> None:
        """One iterated step: point ``step`` at ``t`` taken ``takes`` times, its change left (in
        tolerances) worst at ``port`` by ``absolute``."""
        self.steps += 1
        self.takes += takes
        self.most = max(self.most, takes)
        if change > 1.0:
            self.not_converged += 1
            if change > self._worst_change or not self.worst:
                self._worst_change = change
                self.worst = {"step": step, "t": t, "port": port, "change": absolute,
                              "change_in_tolerances": change if math.isfinite(change) else None}

    def record(self) -> dict[str, Any]:
        """The iteration over the run as ``meta.json`` keeps it: steps, mean and most takes, steps not
        converged, and the worst change left."""
        return {"steps": self.steps, "mean_takes": self.takes / self.steps if self.steps else 0.0,
                "max_takes": self.most, "not_converged": self.not_converged, "worst": self.worst or None}


@dataclass
class StepSizer:
    """The error-controlled macro step: the step to try next, and what the control did."""

    settings: StepControl
    h: float  # the next step to try
    accepted: int = 0
    rejected: int = 0
    forced: int = 0  # steps accepted at minStep although their change was above the tolerance
    smallest: float = math.inf
    largest: float = 0.0

    @classmethod
    def starting(cls, settings: StepControl, first: float) -> "StepSizer":
        """A sizer whose first step is ``first`` bounded to the settings' minStep and maxStep."""
        return cls(settings, min(max(first, settings.minStep), settings.maxStep))

    def judge(self, h: float, change: float) -> float | None:
        """A step of ``h`` over which the inputs changed ``change`` tolerances (input_change):
        None if it stands (and the next step to try is set), else the shorter step to take it
        again with. Judged is the held inputs' error integrated over the step, change·h/2."""
        s = self.settings
        error = change * h / 2
        at_floor = h <= s.minStep * (1 + 1e-9)
        if error > 1.0 and not at_floor:
            self.rejected += 1
            return max(s.minStep, h * max(SHRINK_MOST, math.sqrt(SAFETY / error)))
        self.accepted += 1
        self.forced += error > 1.0
        self.smallest, self.largest = min(self.smallest, h), max(self.largest, h)
        grow = GROW_MOST if error <= 0.0 else min(GROW_MOST, max(SHRINK_MOST, math.sqrt(SAFETY / error)))
        self.h = min(max(h * grow, s.minStep), s.maxStep)
        return None

    def record(self) -> dict[str, Any]:
        """The step control over the run as ``meta.json`` keeps it: steps accepted, rejected, forced at
        minStep, and the smallest and largest step taken."""
        return {"accepted": self.accepted, "rejected": self.rejected, "at_min_step_over_tolerance": self.forced,
                "smallest_step": self.smallest if self.accepted else None,
                "largest_step": self.largest if self.accepted else None}
