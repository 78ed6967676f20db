"""A Model Exchange FMU as a node: the node integrates it over each macro step.

The loop is FMPy's own (``fmpy.simulation.simulateME``), one macro step at a time: CVode
from the SUNDIALS that FMPy ships (or explicit Euler) integrates the continuous states up to
the step's end, stopping at time events (``nextEventTime``), state events (event indicators
changing sign, located by the solver) and step events (``completedIntegratorStep``); at
each the FMU goes to event mode and iterates its discrete states, and the solver starts
again from there. So a run of one ME FMU in hycosim is FMPy's ``simulate_fmu`` of it with
the macro step as output interval.

Between points the solver goes on as in FMPy, keeping its step size and order. It starts
afresh from the FMU's state at a point where that flow breaks: after an event, when an
input changes (inputs are held over a step, so a change is a discontinuity), and where the
state is saved or restored. From a saved state a step is then a function of that state and
the inputs alone, so a step retried after a rollback, or taken by another process from a
checkpoint, gives the values of the first try to the last bit. The default largest solver
step is FMPy's: a fiftieth of the run.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any

from fmpy.fmi1 import FMICallException

from hycosim.core.schema import Node
from hycosim.fmi.instance import FmuInstance
from hycosim.fmi.loader import FmuError, FmuMapping, FmuTerminated

DEFAULT_RELATIVE_TOLERANCE = 1e-5  # FMPy's


class _HeldInputs:
    """What FMPy's solvers call to apply input signals between points: here inputs are held
    over the macro step and set at its start, so there is nothing to apply."""

    def apply(self, *args: Any, **kwargs: Any) -> None:
        pass


class MeInstance(FmuInstance):
    """One instantiated Model Exchange FMU playing one node, with its integrator."""

    def __init__(self, path: Path, node: Node, parameters: dict[str, Any], mapping: FmuMapping,
                 stop_time: float | None):
        super().__init__(path, node, parameters, mapping)
        me = mapping.capabilities
        self.solver_name = node.solver or "CVode"
        self.relative_tolerance = node.relativeTolerance or DEFAULT_RELATIVE_TOLERANCE
        self._max_step = node.maxStep
        self._stop_time = stop_time
        self.needs_completed_step = bool(getattr(me, "needsCompletedIntegratorStep", False))
        self.nx = int(self.md.numberOfContinuousStates or 0)
        self.nz = int(self.md.numberOfEventIndicators or 0)
        self.solver: Any = None
        self._next_event: float | None = None  # the FMU's next time event
        self._restart = False  # the solver starts afresh at the next step
        self._held: dict[str, Any] = {}
        self.events: list[tuple[float, str]] = []  # (time, kind) of the events since the caller last took them

    def _instantiate(self, kwargs: dict[str, Any]) -> Any:
        if self.fmi3:
            from fmpy.fmi3 import FMU3Model

            fmu = FMU3Model(**kwargs)
        else:
            from fmpy.fmi2 import FMU2Model

            fmu = FMU2Model(**kwargs)
        fmu.instantiate()
        return fmu

    # --- lifecycle ------------------------------------------------------------------

    def _after_initialization(self) -> None:
        """After exitInitializationMode: settle the initial event, make the solver."""
        self._iterate_events(self._t0)
        self.solver = self._make_solver(self._t0)

    def _nominals(self) -> Any:
        """The FMU's call for its continuous states' nominal values (the solver's scaling)."""
        return self.fmu.getNominalsOfContinuousStates

    def _make_solver(self, start_time: float) -> Any:
        fmu = self.fmu
        args = dict(nx=self.nx, nz=self.nz, get_x=fmu.getContinuousStates, set_x=fmu.setContinuousStates,
                    get_dx=fmu.getContinuousStateDerivatives if self.fmi3 else fmu.getDerivatives,
                    get_z=fmu.getEventIndicators, input=_HeldInputs())
        if self.solver_name == "Euler":
            from fmpy.simulation import ForwardEuler

            return ForwardEuler(**args)
        from fmpy.sundials import CVodeSolver

        span = (self._stop_time - start_time) if self._stop_time is not None else math.inf
        max_step = self._max_step or (span / 50.0 if math.isfinite(span) and span > 0 else math.inf)
        return CVodeSolver(get_nominals=self._nominals(), set_time=fmu.setTime,
                           startTime=start_time, maxStep=max_step, relativeTolerance=self.relative_tolerance,
                           **args)

    def _iterate_events(self, t: float, kind: str = "") -> None:
        """Event mode at t (``kind``: time, state, step; none at initialisation): iterate the
        discrete states until they settle, then continuous time."""
        if kind:
            self.fmu.enterEventMode()
            self.events.append((t, kind))
        update = self.fmu.updateDiscreteStates if self.fmi3 else self.fmu.newDiscreteStates
        needed, terminate = True, False
        while needed and not terminate:
            needed, terminate, _, _, defined, next_time = update()
        self._settled(t, terminate, next_time if defined else None)
        self.fmu.enterContinuousTimeMode()

    def _settled(self, t: float, terminate: bool, next_event: float | None) -> None:
        """The discrete states settled at t: the FMU's next time event, or its end."""
        if terminate:
            raise FmuTerminated(f"{self.path.name} asked to terminate the simulation at t={t:g} s "
                                "(terminateSimulation)", t)
        self._next_event = next_event

    def _completed_step(self) -> tuple[bool, bool]:
        """completedIntegratorStep: whether an event follows, and whether the FMU ends the run."""
        return self.fmu.completedIntegratorStep()[:2]

    # --- a macro step -----------------------------------------------------------------

    def listed_step(self, inputs: list[str], outputs: list[Any]) -> None:
        """None: a Model Exchange step sets only the inputs that changed (set_inputs), which
        restarts the solver."""
        return None

    def set_inputs(self, values: dict[str, Any]) -> None:
        """Set the inputs that changed (held over the step); the solver starts afresh if any did."""
        changed = {m.port: values[m.port] for m in self.inputs
                   if m.port in values and (m.port not in self._held or self._held[m.port] != values[m.port])}
        if changed:
            super().set_inputs(changed)
            self._held.update(changed)
            self._restart = True

    def set_driven(self, driven: bool) -> None:
        """Set the FMU's driven flag (drivenVariable): a discontinuity, as an input change is."""
        super().set_driven(driven)
        self._restart = self._restart or self.driven_variable is not None

    def do_step(self, t: float, h: float) -> None:
        """Integrate from t to t+h, handling every event inside the step."""
        end = t + h
        eps = 1e-12 * max(1.0, abs(end))
        euler = self._max_step or h
        try:
            if self._restart:
                self.solver.reset(t)
                self._restart = False
            now = t
            while now < end - eps:
                target = min(end, now + euler) if self.solver_name == "Euler" else end
                if self._next_event is not None and self._next_event < target - eps:
                    target = max(self._next_event, now)
                state_event, _, now = self.solver.step(now, target)
                self.fmu.setTime(now)
                step_event = False
                if self.needs_completed_step:
                    step_event, terminate = self._completed_step()
                    if terminate:
                        raise FmuTerminated(f"{self.path.name} asked to terminate the simulation at t={now:g} s "
                                            "(completedIntegratorStep)", now)
                time_event = self._next_event is not None and abs(now - self._next_event) <= eps
                if state_event or time_event or step_event:
                    self._iterate_events(now, "state" if state_event else "time" if time_event else "step")
                    self.solver.reset(now)
        except FMICallException as exc:
            raise FmuError(f"node {self.node!r}: {self.path.name}: integrating from t={t:g} s by {h:g} s failed "
                           f"(status {exc.status})") from None
        except RuntimeError as exc:  # CVode's own failure (too much work, a step size underflow)
            if isinstance(exc, FmuError):
                raise
            raise FmuError(f"node {self.node!r}: {self.path.name}: the solver failed integrating from t={t:g} s "
                           f"by {h:g} s: {exc}") from None
        self.time = end

    # --- state: the FMU's, and the time event it has announced ---------------------------

    def get_state(self) -> Any:
        """The FMU's state, its time, the time event it announced and the inputs it holds."""
        self._restart = True
        return (*super().get_state(), self._next_event, dict(self._held))

    def set_state(self, state: Any) -> None:
        """Back to what :meth:`get_state` gave; the solver starts afresh from there."""
        handle, self.time, self._next_event, held = state
        super().set_state((handle, self.time))
        self._held = dict(held)
        self._restart = True

    def serialize_state(self) -> bytes:
        """The FMU's serialized state (as for co-simulation) after the next time event it announced."""
        upcoming = math.nan if self._next_event is None else self._next_event
        self._restart = True
        return struct.pack("<d", upcoming) + super().serialize_state()

    def deserialize_state(self, data: bytes) -> None:
        """Set what :meth:`serialize_state` gave (in any process); the solver starts afresh."""
        if len(data) < 8:
            raise FmuError(f"node {self.node!r}: {self.path.name}: a serialized state of {len(data)} bytes")
        (upcoming,) = struct.unpack_from("<d", data)
        super().deserialize_state(data[8:])
        self._next_event = None if math.isnan(upcoming) else upcoming
        self._held = {}  # the inputs of the next step are set as changed
        self._restart = True

    def close(self) -> None:
        """Free the solver, then the FMU (as for co-simulation)."""
        self.solver = None  # frees CVode's memory before the FMU goes
        super().close()

