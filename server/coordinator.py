"""The hybrid time/event coordinator (the paper's Equations 3–5).

In the free mode every node follows its own dynamics (Equations 1–2). At each
macro-step point the guards ``when`` of the events are evaluated over the node outputs;
the first that holds switches the co-simulation into that event's mode (Eq. 3): the
links active in it switch on and its driven node follows its driver (Eq. 4). In an
event's mode only its ``until`` guard is evaluated (Eq. 5); when it holds, free running
resumes. One switch at most per macro-step point, so a guard that still holds right
after a release waits for the next point.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from fmu_bridge.config import FREE_MODE, Event
from fmu_bridge.guards import Guard


class GuardEvaluationError(RuntimeError):
    """A guard that could not be evaluated on the values it was given."""


@dataclass(frozen=True)
class ModeSwitch:
    step: int
    t: float
    event: str
    from_mode: str
    to_mode: str
    guard: str
    values: dict[str, Any]

    def as_record(self) -> dict[str, Any]:
        return {"step": self.step, "t": self.t, "event": self.event, "from": self.from_mode,
                "to": self.to_mode, "guard": self.guard, "values": self.values}


class Coordinator:
    def __init__(self, events: list[Event], guards: Mapping[str, tuple[Guard, Guard]]):
        self._events = events
        self._guards = guards
        self.mode = FREE_MODE

    def driven_nodes(self) -> list[str]:
        """Nodes that follow another node instead of their own dynamics in the current mode."""
        return [e.drives for e in self._events if e.name == self.mode]

    def _holds(self, event: str, guard: Guard, values: Mapping[tuple[str, str], Any]) -> bool:
        try:
            return guard.holds(values)
        except Exception as exc:
            raise GuardEvaluationError(
                f"event {event!r}: guard {guard.text!r} failed on {guard.inputs(values)}: {exc}") from None

    def pending_guard_holds(self, values: Mapping[tuple[str, str], Any]) -> bool:
        """Whether the guard that the current mode watches holds, without switching."""
        if self.mode == FREE_MODE:
            return any(self._holds(e.name, self._guards[e.name][0], values) for e in self._events)
        return self._holds(self.mode, self._guards[self.mode][1], values)

    def update(self, step: int, t: float, values: Mapping[tuple[str, str], Any]) -> ModeSwitch | None:
        """Evaluate the guards at a macro-step point; switch mode and report it if one holds."""
        if self.mode == FREE_MODE:
            for event in self._events:
                when, _ = self._guards[event.name]
                if self._holds(event.name, when, values):
                    self.mode = event.name
                    return ModeSwitch(step, t, event.name, FREE_MODE, event.name, when.text, when.inputs(values))
            return None
        _, until = self._guards[self.mode]
        if self._holds(self.mode, until, values):
            event, self.mode = self.mode, FREE_MODE
            return ModeSwitch(step, t, event, event, FREE_MODE, until.text, until.inputs(values))
        return None
