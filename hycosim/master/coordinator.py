"""The hybrid time/event coordinator (the paper's Equations 3–5).

In the free mode every node follows its own dynamics (Equations 1–2). At each
macro-step point the guards ``when`` of the events are evaluated over the node outputs;
the first that holds switches the co-simulation into that event's mode (Eq. 3): the
links active in it switch on and its driven node follows its driver (Eq. 4). In an
event's mode only its ``until`` guard is evaluated (Eq. 5); when it holds, free running
resumes. One switch at most per macro-step point.

Guards fire on a rising edge: after its release an event is disarmed until its ``rearm``
guard holds at a macro-step point (by default: until its ``when`` is seen not to hold).
Without that, a ``when`` that still holds at the release (the gripper opens around the
rod) would switch straight back at the next point, and the run would chatter between
the modes. Re-arming is checked at every point, in any mode, so an edge that passes
while another event's mode is active is not missed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from hycosim.core.schema import FREE_MODE, Event, driven_by_mode

from hycosim.core.config import EventGuards
from hycosim.core.guards import Guard


class GuardEvaluationError(RuntimeError):
    """A guard that could not be evaluated on the values it was given."""


@dataclass(frozen=True)
class ModeSwitch:
    """One mode switch: the point, the event, the modes from and to, the guard that fired and the values
    it read."""

    step: int
    t: float
    event: str
    from_mode: str
    to_mode: str
    guard: str
    values: dict[str, Any]

    def as_record(self) -> dict[str, Any]:
        """The switch as a line of ``events.jsonl``."""
        return {"step": self.step, "t": self.t, "event": self.event, "from": self.from_mode,
                "to": self.to_mode, "guard": self.guard, "values": self.values}


class Coordinator:
    """The run's mode (Equations 5-6): which event is in force, checked against each point's outputs; a
    released event waits for its rearm guard before it fires again."""

    def __init__(self, events: list[Event], guards: Mapping[str, EventGuards]):
        self._events = events
        self._guards = guards
        self._driven = driven_by_mode(events)
        self.mode = FREE_MODE
        self.disarmed: set[str] = set()  # released events waiting for their rearm guard

    def driven_nodes(self) -> list[str]:
        """Nodes that follow another node instead of their own dynamics in the current mode."""
        return list(self._driven.get(self.mode, ()))

    def _holds(self, event: str, guard: Guard, values: Mapping[tuple[str, str], Any]) -> bool:
        try:
            return guard.holds(values)
        except Exception as exc:
            raise GuardEvaluationError(
                f"event {event!r}: guard {guard.text!r} failed on {guard.inputs(values)}: {exc}") from None

    def _rearmed(self, event: str, values: Mapping[tuple[str, str], Any]) -> bool:
        g = self._guards[event]
        if g.rearm is not None:
            return self._holds(event, g.rearm, values)
        return not self._holds(event, g.when, values)

    def pending_guard_holds(self, values: Mapping[tuple[str, str], Any]) -> bool:
        """Whether the guard that the current mode watches holds, without switching.

        In the free mode that is the ``when`` of an armed event: arming changes only at
        the points :meth:`update` evaluates, not at the trial points of a bisection.
        """
        if self.mode == FREE_MODE:
            return any(self._holds(e.name, self._guards[e.name].when, values)
                       for e in self._events if e.name not in self.disarmed)
        return self._holds(self.mode, self._guards[self.mode].until, values)

    def update(self, step: int, t: float, values: Mapping[tuple[str, str], Any]) -> ModeSwitch | None:
        """Evaluate the guards at a macro-step point; switch mode and report it if one holds."""
        if self.disarmed:
            self.disarmed = {name for name in self.disarmed if not self._rearmed(name, values)}
        if self.mode == FREE_MODE:
            for event in self._events:
                if event.name in self.disarmed:
                    continue
                when = self._guards[event.name].when
                if self._holds(event.name, when, values):
                    self.mode = event.name
                    return ModeSwitch(step, t, event.name, FREE_MODE, event.name, when.text, when.inputs(values))
            return None
        until = self._guards[self.mode].until
        if self._holds(self.mode, until, values):
            event, self.mode = self.mode, FREE_MODE
            self.disarmed.add(event)
            return ModeSwitch(step, t, event, event, FREE_MODE, until.text, until.inputs(values))
        return None
