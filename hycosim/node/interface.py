"""The node interface: what a simulator implements to take part in a co-simulation.

A stepping node is advanced by the runtime once per macro step::

    setup(ctx)                      once, before attaching
    outputs()                       its outputs at the current time (also at t0)
    set_mode(mode, driven)          when the coordinator switches mode
    step(t, h, inputs)              integrate from t to t+h on inputs sampled at t
    teardown()                      once, at the end (also after a failure)

A node that can save and restore its state (``can_rollback``) lets the coordinator retry a
step (event localisation, iterative coupling, the error-controlled step); one whose state survives its process as bytes (``can_serialize``)
takes part in checkpoints, so that a run goes on after a crash: a Python node's
``get_state`` returns bytes (:func:`pack_state` of plain lists and numbers) for both.

In a mode where ``driven`` is True the node stops following its own dynamics and
follows its inputs (the paper's s_A = g_B(s_B)); how is the node's business.

An asynchronous source (a camera, a real robot) does not step: the runtime asks it for
the samples it has taken up to a time and publishes them with their timestamps.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import msgpack

from hycosim.core.schema import Port


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
    # Where the run ends (coSimulation.stopTime), for a model that sizes something by it.
    stop_time: float | None = None

    def parameter(self, key: str, default: Any) -> Any:
        """The node's parameter ``key`` from the project file, or ``default``."""
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
    # The outputs that depend on inputs directly, with no state between (y = k·u), each with the
    # inputs it reads: a cycle of links through such ports is an algebraic loop, which
    # ``hycosim validate`` names. None: no output does.
    FEEDTHROUGH: ClassVar[dict[str, frozenset[str]] | None] = None

    @classmethod
    def parameter_problems(cls, parameters: dict[str, Any]) -> list[str]:
        """What is wrong with the values of a node entry's ``parameters``, each a sentence
        naming the parameter (``hycosim.node.parameters`` has the checks). The loader refuses the
        entry with them before the run, as it refuses names outside PARAMETERS. Empty:
        nothing wrong, or the model does not check."""
        return []

    def setup(self, ctx: NodeContext) -> None:
        """Prepare the model; called once before the node attaches."""

    @abstractmethod
    def outputs(self) -> dict[str, Any]:
        """Current output values by port name."""

    @abstractmethod
    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        """Advance from t to t+h; ``inputs`` are the routed values at t."""

    def listed_step(self, inputs: list[str], outputs: list[Port]) -> Callable[[float, float, list[Any]], list[Any]] | None:
        """Optional: a callable ``step(t, h, values)`` doing what step() then outputs() do, on
        the inputs as a sequence (a list or a tuple, one value per port named in ``inputs``, in
        that order; not to be kept or changed) and returning the outputs as a list of their wire
        values (one per port of ``outputs``, in order, each of the type the port declares). It
        raises what step() raises. A run in process steps the node by it, and a node over Zenoh
        every plain release. None (the default): the node is stepped through step() and
        outputs(). An implementation returns None too where the node does not step as the class
        it was written for (:meth:`steps_as`): a subclass that changes step() is stepped by it."""
        return None

    def steps_as(self, cls: type[Node]) -> bool:
        """Whether this node's step() and outputs() are ``cls``'s, which a listed_step written
        for ``cls`` does the work of (a subclass that changes either must be stepped through them)."""
        return type(self).step is cls.step and type(self).outputs is cls.outputs

    def set_mode(self, mode: str, driven: bool) -> None:
        """The coordinator entered ``mode``; ``driven`` says whether this node now follows another."""

    @property
    def start_feedthrough(self) -> dict[str, list[str]]:
        """The outputs whose values at the start depend directly on inputs, each with those inputs
        (none by default: the outputs at the start are what setup made them).

        Between setup and the first step the master gives each node that names some here those
        inputs (:meth:`start_inputs`), as the links carry its peers' start outputs, in the order
        the dependencies give (a cycle: until a fixed point), so that the run's first point is
        consistent."""
        return {}

    def start_inputs(self, inputs: dict[str, Any]) -> None:
        """Take the inputs at the start (every input port, by name) without stepping: outputs()
        then gives the start outputs they make. Called only for a node whose start_feedthrough
        names an output, possibly several times (a loop iterated to its fixed point)."""

    # A model with an initialisation mode of its own (an FMU) stays in it after setup while the
    # master gives the nodes their start inputs, and leaves it when every node has them: the
    # master then gives it its inputs at the start once more (finish_initialization) and takes
    # its outputs, which the run's first point records. A Python model has none.
    @property
    def holds_initialization(self) -> bool:
        """Whether the model is still in an initialisation mode after setup (said in the HELLO)."""
        return False

    def finish_initialization(self, inputs: dict[str, Any]) -> None:
        """Take the inputs at the start (every input port, by name) and leave the initialisation
        mode; outputs() then gives the outputs the run's first point records. Called once, for a
        node whose holds_initialization was true, before its first step."""

    def teardown(self) -> None:
        """Release resources; called once at the end, also after a failure."""

    # Tunable parameters, changed during a run (a scenario's 'parameter' action,
    # sim.set_parameter): a model that has some gives their values now (a bool, int, float or
    # str each) and takes new ones in set_parameters, from its next step on.
    def tunable_values(self) -> dict[str, Any]:
        """Each tunable parameter's current value, by name (none: nothing may be tuned)."""
        return {}

    def set_parameters(self, values: dict[str, Any]) -> None:
        """Take new values of tunable parameters (names from :meth:`tunable_values`, values of
        their types, checked by the runtime) for the steps from now on."""
        raise NodeModelError(f"{type(self).__name__} has no tunable parameters")

    @property
    def can_rollback(self) -> bool:
        """Whether the node can save and restore its state, so that the coordinator may retry a
        macro step (event localisation, iterative coupling, the controlled step). A model that
        overrides get_state and set_state can; one that must not be retried all the same says
        False."""
        return missing_state_methods(type(self)) is None

    @property
    def can_vary_step(self) -> bool:
        """Whether the node takes steps of any length (the error-controlled macro step, event
        localisation); one whose step assumes one fixed h says False, and the run keeps fixed
        steps."""
        return True

    @property
    def can_interpolate(self) -> bool:
        """Whether the node can make its Real inputs follow a polynomial over a step (iterative
        coupling with ``interpolate``): the server then sends their derivatives at the step's
        start with each release (:meth:`set_input_derivatives`)."""
        return False

    def set_input_derivatives(self, derivatives: dict[str, list[float]]) -> None:
        """Over the next step, each input named here follows the Taylor polynomial from its value
        at the step's start with these time derivatives (orders 1, 2, …); any other is held."""
        raise NotImplementedError

    def get_state(self) -> Any:
        """A snapshot of everything the node's step reads (called before a step that may be
        retried, and for checkpoints): bytes, for a node that can serialize."""
        raise NotImplementedError

    def set_state(self, state: Any) -> None:
        """Restore a snapshot taken by get_state (in this process or, as bytes, in another)."""
        raise NotImplementedError

    @property
    def can_serialize(self) -> bool:
        """Whether the node's state survives its process (:meth:`serialize_state`), so that it
        takes part in checkpoints and the run goes on after a crash. A Python node's get_state
        gives bytes: it can where it can roll back."""
        return self.can_rollback

    def serialize_state(self) -> bytes:
        """The node's state as bytes another process of the same node can restore."""
        state = self.get_state()
        if type(state) is not bytes:
            raise NodeModelError(f"{type(self).__name__}.get_state gave a {type(state).__name__}, not bytes: "
                                 "it cannot go into a checkpoint")
        return state

    def deserialize_state(self, data: bytes) -> None:
        """Restore what :meth:`serialize_state` gave."""
        self.set_state(data)


def missing_state_methods(cls: type) -> str | None:
    """What a model class lacks to save and restore its state, said for a message; None if nothing."""
    lacks = [m for m in ("get_state", "set_state") if getattr(cls, m) is getattr(Node, m)]
    return f"its model {cls.__name__} has no {' or '.join(lacks)}" if lacks else None


def pack_state(state: dict[str, Any]) -> bytes:
    """A node's state (plain lists, numbers, strings, bools, None) as bytes: msgpack, which
    keeps every float exact and runs no code when read back, as bytes from a network may not."""
    return msgpack.packb(state, use_bin_type=True)


def unpack_state(data: Any, keys: frozenset[str] | set[str]) -> dict[str, Any]:
    """The state :func:`pack_state` packed; ValueError unless it is a map holding ``keys``."""
    if type(data) is not bytes:
        raise ValueError(f"a state must be bytes, not {type(data).__name__}")
    try:
        state = msgpack.unpackb(data, raw=False, strict_map_key=False)
    except Exception:
        raise ValueError("a state that is not msgpack") from None
    if type(state) is not dict or not set(keys) <= state.keys():
        raise ValueError(f"a state without {', '.join(sorted(set(keys) - (state.keys() if type(state) is dict else set())))}")
    return state


class AsyncSource(ABC):
    """A source that publishes timestamped samples at its own rate instead of stepping."""

    PARAMETERS: ClassVar[frozenset[str] | None] = None  # as for Node
    INPUTS: ClassVar[frozenset[str] | None] = None  # as for Node (an asynchronous node has none)
    OUTPUTS: ClassVar[frozenset[str] | None] = None  # as for Node

    @classmethod
    def parameter_problems(cls, parameters: dict[str, Any]) -> list[str]:
        """What is wrong with the values of a node entry's ``parameters`` (as for Node)."""
        return []

    def setup(self, ctx: NodeContext) -> None:
        """Prepare the source; called once before the node attaches."""

    @abstractmethod
    def samples_until(self, t: float) -> Iterable[tuple[float, dict[str, Any]]]:
        """Samples taken since the last call, up to simulated time t, oldest first. A
        generator's samples are published one by one as it yields them."""

    def teardown(self) -> None:
        """Release resources; called once at the end."""
