"""A node played by any FMI co-simulation FMU, through fmpy."""

from __future__ import annotations

from typing import Any

from fmu_bridge.config import Node as NodeSpec
from fmu_bridge.fmu_loader import FmuInstance

from clients.node import Node, NodeContext


class FmuNode(Node):
    """Ports map to FMU variables by name (a port's ``variable`` renames); node parameters
    and input start values are set before initialisation; one doStep per macro step.

    The driven flag has no FMI call: an FMU that can be driven names an input for it in
    the node's ``drivenVariable``, which set_mode sets before the next doStep.
    """

    def __init__(self, spec: NodeSpec, path):
        self.spec = spec
        self.path = path
        self.fmu: FmuInstance | None = None
        self._checkpoint: Any = None

    def setup(self, ctx: NodeContext) -> None:
        self.fmu = FmuInstance(self.path, self.spec, dict(ctx.parameters))
        self.fmu.initialize(ctx.start_time)

    @property
    def can_rollback(self) -> bool:
        return bool(self.fmu and self.fmu.can_rollback)

    def outputs(self) -> dict[str, Any]:
        return self.fmu.get_outputs()

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        self.fmu.set_inputs(inputs)
        self.fmu.do_step(t, h)

    def set_mode(self, mode: str, driven: bool) -> None:
        self.fmu.set_driven(driven)

    def get_state(self) -> Any:
        state = self.fmu.get_state()
        if self._checkpoint is not None:
            self.fmu.free_state(self._checkpoint)
        self._checkpoint = state
        return state

    def set_state(self, state: Any) -> None:
        self.fmu.set_state(state)

    def teardown(self) -> None:
        if self.fmu is not None:
            self.fmu.close()
