"""A node played by any FMI 1.0, 2.0 or 3.0 FMU, through fmpy: co-simulation, or Model Exchange
integrated by the node (fmi.model_exchange)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import structlog

from hycosim.core.schema import Node as NodeSpec, Port
from hycosim.fmi.instance import FmuInstance
from hycosim.fmi.loader import FmuError, FmuTerminated
from hycosim.fmi.fmu_open import open_fmu

from hycosim.node.interface import Node, NodeContext, NodeModelError, SimulationEnded


def _model_error(exc: FmuError) -> Exception:
    # FmuError stays inside this module: the runtime of a node that plays no FMU never
    # imports fmpy (and numpy), some 13 MB and a tenth of a second per process.
    if isinstance(exc, FmuTerminated):
        return SimulationEnded(exc.t, str(exc))
    return NodeModelError(str(exc))


@contextmanager
def _node_errors() -> Iterator[None]:
    try:
        yield
    except FmuError as exc:
        raise _model_error(exc) from None


class FmuNode(Node):
    """Ports map to FMU variables by name (a port's ``variable`` renames); node parameters
    and input start values are set before initialisation; one doStep per macro step (a Model
    Exchange FMU: its integration over the step).

    The driven flag has no FMI call: an FMU that can be driven names an input for it in
    the node's ``drivenVariable``, which set_mode sets before the next doStep.
    """

    def __init__(self, spec: NodeSpec, path):
        self.spec = spec
        self.path = path
        self.fmu: FmuInstance | None = None
        self._checkpoint: Any = None
        self._derivatives: dict[str, list[float]] = {}  # for the next step's inputs

    def setup(self, ctx: NodeContext) -> None:
        with _node_errors():
            self.fmu = open_fmu(self.path, self.spec, dict(ctx.parameters), ctx.stop_time)
            # It stays in initialisation mode until the master has given every node its start
            # inputs (finish_initialization), as FMI lays out and ECOS and libcosim do: an FMU
            # that computes its outputs only when it leaves that mode (pythonfmu's commonly do)
            # then starts from its linked inputs, not from their start values.
            self.fmu.enter_initialization(ctx.start_time)

    def tunable_values(self) -> dict[str, Any]:
        with _node_errors():
            return self.fmu.tunable_values() if self.fmu is not None else {}

    def set_parameters(self, values: dict[str, Any]) -> None:
        # Between doSteps: FMI lets a tunable parameter be set in step mode.
        with _node_errors():
            for name, value in values.items():
                self.fmu.set_variable(name, value)

    @property
    def can_rollback(self) -> bool:
        return bool(self.fmu and self.fmu.can_rollback)

    @property
    def can_vary_step(self) -> bool:
        return bool(self.fmu and self.fmu.variable_step)

    @property
    def can_interpolate(self) -> bool:
        return bool(self.fmu and self.fmu.can_interpolate)

    def set_input_derivatives(self, derivatives: dict[str, list[float]]) -> None:
        # Given to the FMU after the inputs' values, in step: FMI 2 calls set the derivatives of
        # the values set last, and an FMU may take a new value as one held over the step.
        self._derivatives = derivatives

    @property
    def start_feedthrough(self) -> dict[str, list[str]]:
        return {out: sorted(ins) for out, ins in self.fmu.start_feedthrough().items() if ins} if self.fmu else {}

    def start_inputs(self, inputs: dict[str, Any]) -> None:
        # In initialisation mode: inputs may be set and outputs read there.
        with _node_errors():
            self.fmu.set_inputs(inputs)

    @property
    def holds_initialization(self) -> bool:
        return bool(self.fmu and self.fmu.initializing)

    def finish_initialization(self, inputs: dict[str, Any]) -> None:
        with _node_errors():
            if inputs:
                self.fmu.set_inputs(inputs)
            self.fmu.exit_initialization()

    def _ready(self) -> None:
        """Out of initialisation mode before anything that needs it (a step, a state): where the
        master gave no finish_initialization (a process started again to restore a checkpoint)."""
        if self.fmu is not None and self.fmu.initializing:
            self.finish_initialization({})

    def outputs(self) -> dict[str, Any]:
        try:  # _node_errors written out: a context manager costs a tenth of this call
            return self.fmu.get_outputs()
        except FmuError as exc:
            raise _model_error(exc) from None

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        if self.fmu.initializing:
            self._ready()
        try:  # _node_errors written out, as in outputs
            self.fmu.set_inputs(inputs)
            if self._derivatives:
                self.fmu.set_input_derivatives(self._derivatives)
                self._derivatives = {}
            self.fmu.do_step(t, h)
        except FmuError as exc:
            raise _model_error(exc) from None
        events = getattr(self.fmu, "events", None)  # a Model Exchange FMU's, inside the step
        if events:
            log = structlog.get_logger("node").bind(node=self.spec.nodeName)
            for at, kind in events:
                log.info("fmu event", t=at, kind=kind)
            events.clear()

    def listed_step(self, inputs: list[str], outputs: list[Port]) -> Callable[[float, float, list[Any]], list[Any]] | None:
        """The FMU's step on lists (``FmuInstance.listed_step``), or None: where the FMU's ports
        do not allow it, and for a subclass that changes step() or outputs() (stepped through them)."""
        if not self.steps_as(FmuNode):
            return None
        stepped = self.fmu.listed_step(inputs, outputs) if self.fmu is not None else None
        if stepped is None:
            return None

        fmu = self.fmu

        def step(t: float, h: float, values: list[Any]) -> list[Any]:
            if fmu.initializing:
                self._ready()
            try:  # _node_errors written out, as in outputs
                return stepped(t, h, values)
            except FmuError as exc:
                raise _model_error(exc) from None
        return step

    def set_mode(self, mode: str, driven: bool) -> None:
        with _node_errors():
            self.fmu.set_driven(driven)

    def get_state(self) -> Any:
        self._ready()
        with _node_errors():
            state = self.fmu.get_state()
            if self._checkpoint is not None:
                self.fmu.free_state(self._checkpoint)
        self._checkpoint = state
        return state

    def set_state(self, state: Any) -> None:
        self._ready()
        with _node_errors():
            self.fmu.set_state(state)

    @property
    def can_serialize(self) -> bool:
        return bool(self.fmu and self.fmu.can_serialize)

    def serialize_state(self) -> bytes:
        self._ready()
        with _node_errors():
            return self.fmu.serialize_state()

    def deserialize_state(self, data: bytes) -> None:
        self._ready()
        with _node_errors():
            self.fmu.deserialize_state(data)

    def teardown(self) -> None:
        if self.fmu is not None:
            self.fmu.close()
