"""FMI 1.0 FMUs as nodes, through fmpy's FMI 1.0 classes: co-simulation here, Model Exchange in
fmi.model_exchange (the same integration as FMI 2's, on FMI 1.0's calls).

FMI 1.0 differs from 2.0 where a node notices: an importer sets only start values (inputs and
parameters) before ``fmiInitializeSlave``, which computes the FMU's start from them; there is
no initialisation mode to set linked inputs in and read outputs from before the FMUs leave it,
so the node initialises its FMU whole in its setup, and the initialisation phase gives it its
linked inputs after that, as FMI 1.0 allows before the first ``fmiDoStep``. FMI 1.0 has no
state to get or set: no checkpoints, no retakes, no iteration (``validate`` says so).
"""

from __future__ import annotations

from typing import Any

from fmpy.fmi1 import FMICallException

from hycosim.fmi.instance import FmuInstance
from hycosim.fmi.loader import FmuError
from hycosim.fmi.model_exchange import MeInstance


class Fmi1Instance(FmuInstance):
    """One instantiated FMI 1.0 co-simulation FMU playing one node."""

    def _instantiate(self, kwargs: dict[str, Any]) -> Any:
        from fmpy.fmi1 import FMU1Slave

        fmu = FMU1Slave(**kwargs)
        fmu.instantiate()
        return fmu

    def _enter_initialization(self, start_time: float) -> None:
        """Parameters and start values, then fmiInitializeSlave, which computes from them."""
        self.time = self._t0 = start_time
        for name, value in {**self._starts, **self._parameters}.items():
            self.set_variable(name, value)
        self.fmu.initialize(tStart=start_time)

    def enter_initialization(self, start_time: float) -> None:
        """Initialise the FMU whole: FMI 1.0 has no initialisation mode to hold it in."""
        try:
            self._enter_initialization(start_time)
        except FMICallException as exc:
            raise FmuError(f"node {self.node!r}: initialising {self.path.name} failed ({exc})") from None
        self.initializing = False

    def exit_initialization(self) -> None:
        """Nothing: fmiInitializeSlave did all of it."""
        self.initializing = False

    def _step_refused(self, status: int, t: float, h: float) -> FmuError:
        """FMI 1.0 co-simulation says no more than the status of a doStep it refused."""
        return FmuError(f"node {self.node!r}: {self.path.name}: fmiDoStep from t={t:g} s by {h:g} s was refused "
                        f"(status {status})")


class Fmi1MeInstance(MeInstance):
    """One instantiated FMI 1.0 Model Exchange FMU playing one node, integrated as an FMI 2 one
    is (fmi.model_exchange), on FMI 1.0's calls: fmiInitialize and fmiEventUpdate in place of
    the event mode, whose calls FMI 1.0 does not have."""

    def _instantiate(self, kwargs: dict[str, Any]) -> Any:
        from fmpy.fmi1 import FMU1Model

        fmu = FMU1Model(**kwargs)
        fmu.instantiate()
        return fmu

    def enter_initialization(self, start_time: float) -> None:
        """Parameters and start values at the start time, fmiInitialize (its event settled, as
        fmpy does), and the solver: FMI 1.0 has no initialisation mode to hold the FMU in."""
        self.time = self._t0 = start_time
        try:
            self.fmu.setTime(start_time)
            for name, value in {**self._starts, **self._parameters}.items():
                self.set_variable(name, value)
            converged, _, _, terminate, defined, next_time = self.fmu.initialize()
            while not converged and not terminate:
                converged, _, _, terminate, defined, next_time = self.fmu.eventUpdate()
            self._settled(start_time, terminate, next_time if defined else None)
            self.solver = self._make_solver(start_time)
        except FMICallException as exc:
            raise FmuError(f"node {self.node!r}: initialising {self.path.name} failed ({exc})") from None
        self.initializing = False

    def exit_initialization(self) -> None:
        """Nothing: fmiInitialize did all of it."""
        self.initializing = False

    def _iterate_events(self, t: float, kind: str = "") -> None:
        """At an event at t: fmiEventUpdate until the discrete states settle."""
        if kind:
            self.events.append((t, kind))
        converged, terminate = False, False
        while not converged and not terminate:
            converged, _, _, terminate, defined, next_time = self.fmu.eventUpdate()
        self._settled(t, terminate, next_time if defined else None)

    def _completed_step(self) -> tuple[bool, bool]:
        """FMI 1.0's completedIntegratorStep says only whether an event update follows."""
        return self.fmu.completedIntegratorStep(), False

    def _nominals(self) -> Any:
        return self.fmu.getNominalContinuousStates
