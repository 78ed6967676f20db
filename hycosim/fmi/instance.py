"""One instantiated FMU playing one node: a thin call into fmpy's FMI 1.0, 2.0 or 3.0 slave for
each thing the node runtime needs (set inputs, step, get outputs, save and restore state).

What it loads is checked first (:func:`hycosim.fmi.loader.check_fmu`); a Model Exchange FMU is
the same with an integrator inside its step (:mod:`hycosim.fmi.model_exchange`). Every failure
is an :class:`~hycosim.fmi.loader.FmuError` that names the node and, where there is one, the
variable.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import struct
import tempfile
from ctypes import c_double
from pathlib import Path
from typing import Any, Callable

import fmpy
from fmpy.fmi1 import FMICallException
from fmpy.model_description import ScalarVariable

from hycosim.core.schema import Node, PortType
from hycosim.core.schema import Port as NodePort
from hycosim.fmi.loader import (CO_SIMULATION, FmuError, FmuMapping, FmuTerminated, array_elements, check_fmu,
                                clock_ticks, json_excerpt, shape_of)
from hycosim.fmi.value_access import Port, bare_function, port_access

_DISCARD = 2  # fmi2Discard and fmi3Discard
# A node port's values as Python has them (String and Binary ports are never read in one call).
_PYTHON_TYPES = {PortType.REAL: float, PortType.INTEGER: int, PortType.BOOLEAN: bool}


class FmuInstance:
    """One instantiated co-simulation FMU playing one node."""

    def __init__(self, path: Path, node: Node, parameters: dict[str, Any], mapping: FmuMapping | None = None):
        self.path = path
        self.node = node.nodeName
        mapping = mapping or check_fmu(path, node, parameters)
        self.md, self.inputs, self.outputs, self.driven_variable = (
            mapping.md, mapping.inputs, mapping.outputs, mapping.driven)
        self.start_feedthrough = mapping.start_feedthrough
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.fmi1 = self.md.fmiVersion.startswith("1")  # fmpy's FMI 1.0 classes take FMI 2's calls
        cs = mapping.capabilities
        self.can_rollback = bool(getattr(cs, "canGetAndSetFMUstate", False))
        self.can_serialize = self.can_rollback and bool(getattr(cs, "canSerializeFMUstate", False))
        self.variable_step = mapping.variable_step
        self.event_mode = bool(self.fmi3 and getattr(cs, "hasEventMode", False))
        self.early_return = bool(self.fmi3 and getattr(cs, "canReturnEarlyAfterIntermediateUpdate", False))
        # Its clocks, each an input clock of a constant interval (check_fmu refuses any other).
        self.clocks = mapping.clocks
        self._t0 = 0.0
        self.initializing = False  # in initialisation mode (enter_initialization to exit_initialization)
        # FMI 2 only: FMI 3 co-simulation has no input derivatives.
        self.can_interpolate = not self.fmi3 and bool(getattr(cs, "canInterpolateInputs", False))
        self._variables = {v.name: v for v in self.md.modelVariables}
        self._starts = {p.variable or p.name: p.start_value() for p in node.input if p.start is not None}
        self._parameters = parameters
        self._unzipdir = tempfile.mkdtemp(prefix=f"hycosim-{self.node}-")
        fmpy.extract(str(path), self._unzipdir)
        # fmpy changes into the binary's folder to load it and does not change back when the
        # load fails: the folder is removed below, which would leave this process (a Python
        # caller's, in process) in a folder that is gone.
        cwd = os.getcwd()
        try:
            self.fmu = self._instantiate(dict(guid=self.md.guid, unzipDirectory=self._unzipdir,
                                              modelIdentifier=cs.modelIdentifier, instanceName=self.node))
        except Exception as exc:  # a binary without the interface's functions, or one that fails to load
            os.chdir(cwd)
            shutil.rmtree(self._unzipdir, ignore_errors=True)
            raise FmuError(f"node {self.node!r}: {path.name}: its binary cannot be loaded as {mapping.interface} "
                           f"({type(exc).__name__}: {exc})") from None
        self.time = 0.0
        # The ports a step reads and writes, one C call per type (None: through fmpy's calls one by one).
        # FMI 1.0's C functions carry the model identifier in their names: through fmpy's calls.
        self._reader = None if self.fmi1 else port_access(
            self.fmu, [Port(m.vr, m.type, m.size) for m in self.outputs], self.fmi3, False)
        self._output_ports = [m.port for m in self.outputs]
        self._writer = None if self.fmi1 else port_access(
            self.fmu, [Port(m.vr, m.type, m.size) for m in self.inputs], self.fmi3, True)
        # fmi2DoStep called straight (a step's call less), on arguments converted here or per
        # call (value_access.bare_function); None where fmpy's call is used.
        self._do_step_c = (bare_function(self.fmu.dll, "fmi2DoStep") if mapping.interface == CO_SIMULATION
                           and not self.fmi3 and not self.fmi1 and getattr(self.fmu, "fmiCallLogger", None) is None else None)
        self._component = ctypes.c_void_p(self.fmu.component)

    def _instantiate(self, kwargs: dict[str, Any]) -> Any:
        """The fmpy object of the FMU's co-simulation interface, instantiated."""
        if self.fmi3:
            from fmpy.fmi3 import FMU3Slave

            fmu = FMU3Slave(**kwargs)
            fmu.instantiate(eventModeUsed=self.event_mode, earlyReturnAllowed=self.early_return)
        else:
            from fmpy.fmi2 import FMU2Slave

            fmu = FMU2Slave(**kwargs)
            fmu.instantiate()
        return fmu

    # --- values ---------------------------------------------------------------------

    def _set(self, var: ScalarVariable, value: Any, size: int | None = None) -> None:
        """Set one variable: a scalar, or (``size``) every element of an array variable from a list."""
        vr = [var.valueReference]
        t = var.type
        values = [value] if size is None else value
        try:
            if t in ("Real", "Float64"):
                (self.fmu.setFloat64 if self.fmi3 else self.fmu.setReal)(vr, [float(v) for v in values])
            elif t == "Float32":
                self.fmu.setFloat32(vr, [float(v) for v in values])
            elif t == "Boolean":
                self.fmu.setBoolean(vr, [bool(v) for v in values])
            elif t == "String":
                self.fmu.setString(vr, [str(v) for v in values])
            elif t == "Binary":
                self.fmu.setBinary(vr, [bytes(v) for v in values])
            elif self.fmi3:
                getattr(self.fmu, f"set{t if t != 'Enumeration' else 'Int64'}")(vr, [int(v) for v in values])
            else:
                self.fmu.setInteger(vr, [int(v) for v in values])
        except FMICallException as exc:
            raise FmuError(f"node {self.node!r}: setting {var.name!r} = {value!r} failed ({exc})") from None

    def _get(self, vr: int, t: str, size: int | None = None) -> Any:
        """Read one variable: a scalar, or (``size``) an array variable's elements as a list."""
        if size is not None:
            return self._get_array(vr, t, size)
        if t in ("Real", "Float64"):
            return (self.fmu.getFloat64 if self.fmi3 else self.fmu.getReal)([vr])[0]
        if t == "Float32":
            return self.fmu.getFloat32([vr])[0]
        if t == "Boolean":
            return bool(self.fmu.getBoolean([vr])[0])
        if t == "String":
            return self.fmu.getString([vr])[0]
        if t == "Binary":
            return self.fmu.getBinary([vr])[0] or b""  # a null pointer: no bytes
        if self.fmi3:
            return int(getattr(self.fmu, f"get{t if t != 'Enumeration' else 'Int64'}")([vr])[0])
        return int(self.fmu.getInteger([vr])[0])

    def _get_array(self, vr: int, t: str, size: int) -> list[Any]:
        # Only FMI 3 has arrays, and only of the types an array port takes (Real, Integer, Boolean).
        if t == "Boolean":
            return [bool(v) for v in self.fmu.getBoolean([vr], size)]
        if t in ("Float64", "Float32"):
            return list(getattr(self.fmu, f"get{t}")([vr], size))
        return [int(v) for v in getattr(self.fmu, f"get{t if t != 'Enumeration' else 'Int64'}")([vr], size)]

    def set_variable(self, name: str, value: Any) -> None:
        """Set a parameter or start value by FMU variable name (an array variable from a list,
        flat or nested as its shape: :func:`array_elements`)."""
        var = self._variables.get(name)
        if var is None:
            raise FmuError(f"node {self.node!r}: parameter {name!r} is not a variable of {self.path.name}")
        if not getattr(var, "dimensions", None):
            self._set(var, value)
            return
        elements = array_elements(value, shape_of(self.md, var, self._parameters, self.path))
        if elements is None:
            raise FmuError(f"node {self.node!r}: {name!r} is an array variable of {self.path.name}, and "
                           f"{json_excerpt(value)} does not have its shape")
        self._set(var, elements, len(elements))

    def tunable_values(self) -> dict[str, Any]:
        """The FMU's tunable parameters (causality parameter, variability tunable; scalars of
        a type other than Binary), each with its value now."""
        found = {}
        for var in self.md.modelVariables:
            if (var.causality == "parameter" and var.variability == "tunable" and var.type != "Binary"
                    and not getattr(var, "dimensions", None)):
                value = self._get(var.valueReference, var.type)
                found[var.name] = float(value) if var.type in ("Real", "Float64", "Float32") else value
        return found

    def set_driven(self, driven: bool) -> None:
        """Tell the FMU, through its ``drivenVariable`` (if any), whether an event drives it."""
        if self.driven_variable is not None:
            self._set(self.driven_variable, driven)

    def set_inputs(self, values: dict[str, Any]) -> None:
        """Set the inputs given by port (all of them in one C call per type, where they can be)."""
        # All of them (a step's), or some (a Model Exchange FMU's changed ones: one by one below).
        if self._writer is not None and len(values) == len(self.inputs):
            try:
                self._writer.write([values[m.port] for m in self.inputs])
            except FMICallException as exc:
                raise self._inputs_failed(exc) from None
            return
        for m in self.inputs:
            if m.port in values:
                self._set(self._variables[m.variable], values[m.port], m.size)

    def listed_step(self, inputs: list[str], outputs: list[NodePort]) -> Callable[[float, float, list[Any]], list[Any]] | None:
        """A macro step on lists: ``step(t, h, values)`` sets the inputs from ``values`` (one per
        port of ``inputs``, in that order), steps from t to t+h and returns the outputs, one
        per port of ``outputs`` in order, in the Python types those ports declare. That is
        set_inputs, do_step and get_outputs without a dict between them: the node's wire order
        is the FMU's port order, and no value needs a conversion after its read. None where
        that does not hold (ports in another order, a value of another type, a port read one
        by one) and the dict calls must be used."""
        reader, writer = self._reader, self._writer
        if reader is None or writer is None or [m.port for m in self.inputs] != inputs \
                or self._output_ports != [p.name for p in outputs] \
                or reader.conversions() != [_PYTHON_TYPES.get(p.type) for p in outputs]:
            return None

        do_step_c, component = self._do_step_c, self._component

        def step(t: float, h: float, values: list[Any]) -> list[Any]:
            try:
                writer.write(values)
            except FMICallException as exc:
                raise self._inputs_failed(exc) from None
            if do_step_c is None:
                self.do_step(t, h)
            else:  # do_step's FMI 2 call, made here: a step's call less for each node
                status = do_step_c(component, c_double(t), c_double(h), 1)
                if status > 1:  # fmi2Warning
                    raise self._step_refused(status, t, h)
                self.time = t + h
            try:
                return reader.read()
            except FMICallException as exc:
                raise self._outputs_failed(exc) from None
        return step

    def set_input_derivatives(self, derivatives: dict[str, list[float]]) -> None:
        """Give Real inputs (by port) their time derivatives at the next step's start, orders 1,
        2, …: over that step each follows the Taylor polynomial from the value set_inputs gave
        (fmi2SetRealInputDerivatives; the FMU must declare canInterpolateInputs)."""
        vrs, orders, values = [], [], []
        for m in self.inputs:
            for order, value in enumerate(derivatives.get(m.port, ()), start=1):
                vrs.append(m.vr)
                orders.append(order)
                values.append(float(value))
        if not vrs:
            return
        try:
            self.fmu.setRealInputDerivatives(vrs, orders, values)
        except FMICallException as exc:
            raise FmuError(f"node {self.node!r}: setting input derivatives failed ({exc})") from None

    def get_outputs(self) -> dict[str, Any]:
        """Every output's value by port (an array's as a list of its elements)."""
        try:
            if self._reader is not None:
                return dict(zip(self._output_ports, self._reader.read()))
            return {m.port: self._get(m.vr, m.type, m.size) for m in self.outputs}
        except FMICallException as exc:
            raise self._outputs_failed(exc) from None

    def _inputs_failed(self, exc: FMICallException) -> FmuError:
        return FmuError(f"node {self.node!r}: setting inputs {', '.join(m.variable for m in self.inputs)} "
                        f"failed ({exc})")

    def _outputs_failed(self, exc: FMICallException) -> FmuError:
        return FmuError(f"node {self.node!r}: reading outputs failed ({exc})")

    # --- lifecycle ------------------------------------------------------------------

    def _enter_initialization(self, start_time: float) -> None:
        """Set parameters and input start values, then into initialisation mode (both interfaces)."""
        self.time = self._t0 = start_time
        if not self.fmi3:
            self.fmu.setupExperiment(startTime=start_time)
        values = {**self._starts, **self._parameters}
        # Structural parameters first: they size the arrays set after them (and may reset them).
        for name in sorted(values, key=lambda n: getattr(self._variables.get(n), "causality", "") != "structuralParameter"):
            self.set_variable(name, values[name])
        if self.fmi3:
            self.fmu.enterInitializationMode(startTime=start_time)
        else:
            self.fmu.enterInitializationMode()

    def _after_initialization(self) -> None:
        """What follows exitInitializationMode (FMI 3 with event mode: settle its first event)."""
        if self.event_mode:
            self._handle_events()

    def enter_initialization(self, start_time: float) -> None:
        """Set parameters and start values and enter initialisation mode at ``start_time``, where
        the start inputs are set and the outputs read (``set_inputs``, ``get_outputs``) before
        every FMU of the system leaves it (:meth:`exit_initialization`), as FMI lays out."""
        try:
            self._enter_initialization(start_time)
        except FMICallException as exc:
            raise FmuError(f"node {self.node!r}: initialising {self.path.name} failed ({exc})") from None
        self.initializing = True

    def exit_initialization(self) -> None:
        """Leave initialisation mode: the FMU computes from the start inputs set in it."""
        try:
            self.fmu.exitInitializationMode()
            self._after_initialization()
        except FMICallException as exc:
            raise FmuError(f"node {self.node!r}: initialising {self.path.name} failed ({exc})") from None
        finally:
            self.initializing = False

    def initialize(self, start_time: float) -> None:
        """Initialise the FMU at ``start_time`` in one call: into initialisation mode and out."""
        self.enter_initialization(start_time)
        self.exit_initialization()

    def _handle_events(self, t: float | None = None) -> None:
        """FMI 3 event mode (at ``t``, None: after initialisation): iterate the discrete states
        until settled, then back to step mode; FmuTerminated where the FMU asks to end there."""
        while True:
            update, terminate = self.fmu.updateDiscreteStates()[:2]
            if terminate:
                at = self._t0 if t is None else t
                raise FmuTerminated(f"{self.path.name} asked to terminate the simulation at t={at:g} s "
                                    "(terminateSimulation in event mode)", at)
            if not update:
                break
        self.fmu.enterStepMode()

    def _tick(self, at: float, vrs: list[int]) -> None:
        """Tick the clocks ``vrs`` at ``at``: event mode, the clocks set, the clocked partitions
        run (updateDiscreteStates), back to step mode. The inputs are those set for the step."""
        try:
            self.fmu.enterEventMode()
            self.fmu.setClock(vrs, [True] * len(vrs))
            self._handle_events(at)
        except FMICallException as exc:
            names = ", ".join(c.name for c in self.clocks if c.vr in vrs)
            raise FmuError(f"node {self.node!r}: {self.path.name}: ticking clock {names} at t={at:g} s failed "
                           f"({exc})") from None

    def do_step(self, t: float, h: float) -> None:
        """Advance from t to t+h; the FMU's own micro-steps stay inside it."""
        try:
            if self._do_step_c is not None:
                # noSetFMUStatePriorToCurrentPoint, as fmpy
                status = self._do_step_c(self._component, c_double(t), c_double(h), 1)
                if status > 1:  # fmi2Warning
                    raise FMICallException(function="fmi2DoStep", status=status)
            elif not self.fmi3:
                self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            else:
                end, now = t + h, t
                try:
                    ticks = clock_ticks(self.clocks, self._t0, t, end) if self.clocks else ()
                except ValueError as exc:
                    raise FmuError(f"node {self.node!r}: {self.path.name}: {exc}") from None
                # A tick at t comes before the step, on its inputs; one inside it cuts the step there.
                for at, vrs in ticks:
                    if at - now > 1e-9 * max(1.0, abs(end)):
                        self._step3(now, at)
                        now = at
                    self._tick(at, vrs)
                self._step3(now, end)
        except FMICallException as exc:
            raise self._step_refused(exc.status, t, h) from None
        self.time = t + h

    def _step_refused(self, status: int, t: float, h: float) -> FmuError:
        """The error of a doStep from t by h that returned ``status`` (above fmi2Warning)."""
        if status != _DISCARD:
            return FmuError(f"node {self.node!r}: {self.path.name}: doStep from t={t:g} s by {h:g} s failed "
                            f"(status {status})")
        if not self.fmi3:
            ended = self._fmi2_terminated()
            if ended is not None:
                return FmuTerminated(f"{self.path.name} asked to terminate the simulation at t={ended:g} s "
                                     "(fmi2Discard with fmi2Terminated)", ended)
        return FmuError(f"node {self.node!r}: {self.path.name} discarded doStep from t={t:g} s by {h:g} s "
                        f"({'fmi3' if self.fmi3 else 'fmi2'}Discard) without asking to terminate")

    def _step3(self, now: float, end: float) -> None:
        """FMI 3 doStep calls from ``now`` to ``end``: an early return goes on from where it
        stopped, an event the FMU met is settled in event mode."""
        while now < end - 1e-12 * max(1.0, abs(end)):
            event, terminate, early, last = self.fmu.doStep(currentCommunicationPoint=now,
                                                            communicationStepSize=end - now)
            if terminate:
                raise FmuTerminated(f"{self.path.name} asked to terminate the simulation at t={last:g} s "
                                    "(terminateSimulation)", last)
            if event and self.event_mode:
                self.fmu.enterEventMode()
                self._handle_events(last if early else end)
            now = last if early else end

    def _fmi2_terminated(self) -> float | None:
        """After an fmi2Discard: the time the FMU ended the simulation at, or None if it did not."""
        from fmpy.fmi2 import fmi2LastSuccessfulTime, fmi2Terminated

        try:
            if not self.fmu.getBooleanStatus(fmi2Terminated):
                return None
        except FMICallException:  # an FMU that cannot say: a plain discard
            return None
        try:
            return self.fmu.getRealStatus(fmi2LastSuccessfulTime)
        except FMICallException:
            return self.time

    def get_state(self) -> Any:
        """The FMU's state and the communication time it is at (fmi2GetFMUstate / fmi3GetFMUState);
        FmuError naming the node where the FMU cannot get and set its state."""
        if not self.can_rollback:
            raise FmuError(f"node {self.node!r}: {self.path.name} cannot get and set its state")
        return (self.fmu.getFMUState() if self.fmi3 else self.fmu.getFMUstate()), self.time

    def set_state(self, state: Any) -> None:
        """Set the FMU back to a state :meth:`get_state` gave, and its time with it."""
        handle, self.time = state
        (self.fmu.setFMUState if self.fmi3 else self.fmu.setFMUstate)(handle)

    def free_state(self, state: Any) -> None:
        """Free a state :meth:`get_state` gave (the FMU holds its memory until then)."""
        (self.fmu.freeFMUState if self.fmi3 else self.fmu.freeFMUstate)(state[0])

    def serialize_state(self) -> bytes:
        """The FMU's current state as bytes that outlive this process (fmi2SerializeFMUstate /
        fmi3SerializeFMUState), prefixed by the communication time it is at."""
        if not self.can_serialize:
            raise FmuError(f"node {self.node!r}: {self.path.name} cannot serialize its state (canSerializeFMUstate)")
        try:
            handle = self.fmu.getFMUState() if self.fmi3 else self.fmu.getFMUstate()
            try:
                data = (self.fmu.serializeFMUState if self.fmi3 else self.fmu.serializeFMUstate)(handle)
            finally:
                (self.fmu.freeFMUState if self.fmi3 else self.fmu.freeFMUstate)(handle)
        except FMICallException as exc:
            raise FmuError(f"node {self.node!r}: {self.path.name}: serializing its state failed ({exc})") from None
        return struct.pack("<d", self.time) + bytes(data)

    def deserialize_state(self, data: bytes) -> None:
        """Set the state :meth:`serialize_state` gave (from this FMU, in any process)."""
        if len(data) < 8:
            raise FmuError(f"node {self.node!r}: {self.path.name}: a serialized state of {len(data)} bytes")
        (t,) = struct.unpack_from("<d", data)
        try:
            if self.fmi3:
                handle = self.fmu.deserializeFMUState(data[8:])
                self.fmu.setFMUState(handle)
                self.fmu.freeFMUState(handle)
            else:
                handle = self.fmu.deSerializeFMUstate(data[8:])
                self.fmu.setFMUstate(handle)
                self.fmu.freeFMUstate(handle)
        except FMICallException as exc:
            raise FmuError(f"node {self.node!r}: {self.path.name}: restoring a serialized state failed ({exc})") from None
        self.time = t

    def close(self) -> None:
        """Terminate the FMU and free its instance; errors on the way out are let go (the FMU may have
        failed already)."""
        try:
            self.fmu.terminate()
        except Exception:
            pass
        try:
            self.fmu.freeInstance()
        except Exception:
            pass
        shutil.rmtree(self._unzipdir, ignore_errors=True)
