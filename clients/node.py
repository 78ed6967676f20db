"""The node interface: what a simulator implements to take part in a co-simulation.

A stepping node is advanced by the runtime once per macro step::

    setup(ctx)                      once, before attaching
    outputs()                       its outputs at the current time (also at t0)
    set_mode(mode, driven)          when the coordinator switches mode
    step(t, h, inputs)              integrate from t to t+h on inputs sampled at t
    teardown()                      once, at the end (also after a failure)

In a mode where ``driven`` is True the node stops following its own dynamics and
follows its inputs (the paper's s_A = g_B(s_B)); how is the node's business.

An asynchronous source (a camera, a real robot) does not step: the runtime asks it for
the samples it has taken up to a time and publishes them with their timestamps.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from fmu_bridge.config import Port


@dataclass
class NodeContext:
    """What a node knows about its place in the co-simulation."""

    name: str
    uid: int
    inputs: list[Port]
    outputs: list[Port]
    parameters: dict[str, Any]
    step_size: float
    start_time: float
    project_dir: Path = field(default_factory=Path.cwd)
    # Wall seconds per simulated second in a real-time run (coSimulation.realTime); None: the
    # run goes as fast as it can, and simulated time has nothing to do with the wall clock.
    real_time: float | None = None

    def parameter(self, key: str, default: Any) -> Any:
        return self.parameters.get(key, default)


class NodeModelError(RuntimeError):
    """A model that cannot go on, with a message for the user that names the node: the
    runtime reports it as it is (any other exception is reported with its type)."""


class SimulationEnded(Exception):
    """Raised by a model's ``step`` to end the simulation at time ``t`` (an FMU that asked to
    terminate): the run ends cleanly at the last macro-step point every node reached, and
    the run's records name this node, the time and the message."""

    def __init__(self, t: float, message: str):
        super().__init__(message)
        self.t = t


class Node(ABC):
    """A simulator advanced in macro steps by the runtime."""

    # The parameter names the model reads, if it declares them: a node entry giving any
    # other is refused at load, since a misspelt parameter would leave its default in
    # place without a word. None: not declared (the model reads what it likes).
    PARAMETERS: ClassVar[frozenset[str] | None] = None
    # Likewise the input ports the model reads and the outputs it gives: an entry naming any
    # other port is refused at load (an input read with a default, misspelt in the project
    # file, would keep its default for the whole run). None: not declared.
    INPUTS: ClassVar[frozenset[str] | None] = None
    OUTPUTS: ClassVar[frozenset[str] | None] = None

    def setup(self, ctx: NodeContext) -> None:
        """Prepare the model; called once before the node attaches."""

    @abstractmethod
    def outputs(self) -> dict[str, Any]:
        """Current output values by port name."""

    @abstractmethod
    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        """Advance from t to t+h; ``inputs`` are the routed values at t."""

    def set_mode(self, mode: str, driven: bool) -> None:
        """The coordinator entered ``mode``; ``driven`` says whether this node now follows another."""

    def teardown(self) -> None:
        """Release resources; called once at the end, also after a failure."""

    # Rollback, for event localisation: a node that can save and restore its state lets
    # the coordinator retry a macro step with a smaller step size.
    @property
    def can_rollback(self) -> bool:
        return False

    def get_state(self) -> Any:
        """A snapshot of the node's state (called before a step that may be retried)."""
        raise NotImplementedError

    def set_state(self, state: Any) -> None:
        """Restore a snapshot taken by get_state."""
        raise NotImplementedError


class AsyncSource(ABC):
    """A source that publishes timestamped samples at its own rate instead of stepping."""

    PARAMETERS: ClassVar[frozenset[str] | None] = None  # as for Node
    INPUTS: ClassVar[frozenset[str] | None] = None  # as for Node (an asynchronous node has none)
    OUTPUTS: ClassVar[frozenset[str] | None] = None  # as for Node

    def setup(self, ctx: NodeContext) -> None:
        """Prepare the source; called once before the node attaches."""

    @abstractmethod
    def samples_until(self, t: float) -> Iterable[tuple[float, dict[str, Any]]]:
        """Samples taken since the last call, up to simulated time t, oldest first. A
        generator's samples are published one by one as it yields them."""

    def teardown(self) -> None:
        """Release resources; called once at the end."""
