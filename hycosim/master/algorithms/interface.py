"""The master algorithm's interface: how the step from one macro-step point is taken.

The relay owns the barrier (releases out, outputs in, the routed inputs) and the loop; an
algorithm decides how a step is taken over it: once by every node at once (Jacobi), node by
node (Gauss-Seidel), again until its inputs settle (iterated), shorter while they change too
much (step control), bisected around a guard crossing (localised). It sees the barrier only
through :class:`Barrier`, so that one written outside hycosim takes steps as the built-in ones
do. ``docs/master-algorithms.md`` says how to write one.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

Said = Mapping[str, Mapping[str, Any]]
Inputs = dict[str, list[Any]]


class AlgorithmError(RuntimeError):
    """A step the run cannot go on from (one that did not converge, with ``onFailure: stop``);
    the message names the step. The run ends failed, its records kept."""


@dataclass(slots=True)
class StepRequest:
    """The step the loop asks for: from point ``k`` at ``t`` over ``h`` seconds in ``mode``.

    ``times``: a batched release's base points (``[t, …, t + h]``; None: one step).
    ``record``: records point k with the inputs the barrier holds when it is called. Call it
    exactly once: right after the (first) release is sent, so that the record is written while
    the nodes integrate, or after the last take, when the inputs a step was taken on are only
    known then (an iterated step's)."""

    k: int
    t: float
    h: float
    mode: str
    record: Callable[[], None]
    times: list[float] | None = None


@dataclass(slots=True)
class StepTaken:
    """How a step went: the length that stood (shorter than asked for: the next point is
    there, and a new grid of stepSize starts from it), each node's answer in seconds after
    its release, the wait for the last answer, the takes, and a located event's window."""

    h: float
    arrivals: dict[str, float]
    wait: float
    takes: int = 1
    localised: dict[str, Any] = field(default_factory=dict)


class Barrier(Protocol):
    """What the relay gives an algorithm: one exchange with the nodes, a rollback, the inputs."""

    input_labels: Mapping[str, list[str]]  # node → its inputs as ``node.port``
    order: list[str]  # Gauss-Seidel's order of the stepping nodes
    meta: dict[str, Any]  # the run's meta.json, written at the end however the run ends

    def exchange(self, nodes: list[str] | None, k: int, t: float, h: float, mode: str, *,
                 times: list[float] | None = None, inputs: Inputs | None = None,
                 slopes: dict[str, Any] | None = None, meanwhile: Callable[[], None] | None = None,
                 since: float | None = None) -> dict[str, float]:
        """Release step k (t → t + h) to ``nodes`` (None: every node due at k) on ``inputs``
        (None: the routed ones), run ``meanwhile`` once the release is out, and gather the
        outputs due at its end; return each answer's seconds after ``since`` (default: the
        release)."""

    def rollback(self, k: int, t: float) -> None:
        """Tell every node to go back to point k (t), where it saved its state before the step."""

    @property
    def inputs(self) -> Inputs:
        """The inputs the next exchange steps on (routed at the point; the dict itself)."""

    @inputs.setter
    def inputs(self, value: Inputs) -> None: ...

    def route_into(self, node: str, mode: str) -> None:
        """Route ``node``'s inputs again from the outputs the barrier holds now."""

    def candidate(self, mode: str) -> Inputs:
        """The inputs the outputs held now would route to, leaving the barrier's as they are."""

    def guard_pending(self) -> bool:
        """Whether an event's guard that is not in force holds on the outputs held now."""


class MasterAlgorithm(Protocol):
    """How a macro step is taken. The relay asks :meth:`plan` once, when the nodes have said
    what they can do, and then calls :meth:`step` for every step of the run."""

    def plan(self, said: Said, barrier: Barrier) -> MasterAlgorithm:
        """The algorithm that runs, given what each stepping node said it can do (its HELLO's
        capabilities): this one, or the one it falls back to (saying why in ``barrier.meta``)."""

    def step(self, barrier: Barrier, request: StepRequest) -> StepTaken:
        """Take the step asked for and return how it went."""

    def step_length(self) -> float | None:
        """The length the next step should have, if the algorithm chooses it (None: stepSize)."""

    def startup_steps(self) -> int:
        """How many steps of stepSize / STARTUP_SPLIT open the run (interpolated inputs need points)."""

    def frames_only(self) -> str:
        """Why its releases must go as frames even in process (what a call cannot carry), or ""."""

    def checkpoint(self) -> dict[str, Any]:
        """What a checkpoint keeps of it (JSON), beside the server's state."""

    def restore(self, kept: Mapping[str, Any], barrier: Barrier, what: str) -> None:
        """Take back what :meth:`checkpoint` kept (``what`` names the checkpoint for errors)."""


class Algorithm(MasterAlgorithm, ABC):
    """A base for master algorithms: :meth:`step` to write, the rest of
    :class:`MasterAlgorithm` as a plain one-take algorithm needs it."""

    def plan(self, said: Said, barrier: Barrier) -> MasterAlgorithm:
        return self

    @abstractmethod
    def step(self, barrier: Barrier, request: StepRequest) -> StepTaken:
        """Take the step asked for and return how it went."""

    def step_length(self) -> float | None:
        return None

    def startup_steps(self) -> int:
        return 0

    def frames_only(self) -> str:
        return ""

    def checkpoint(self) -> dict[str, Any]:
        return {}

    def restore(self, kept: Mapping[str, Any], barrier: Barrier, what: str) -> None:
        return None


class Coupling(Algorithm):
    """A coupling scheme: how one take of a step goes (all at once, or node by node). The
    wrapping algorithms (iterated, step-controlled, localised) retake steps through it."""

    @abstractmethod
    def take(self, barrier: Barrier, k: int, t: float, h: float, mode: str, *,
             times: list[float] | None = None, meanwhile: Callable[[], None] | None = None,
             inputs: Inputs | None = None, slopes: dict[str, Any] | None = None) -> tuple[dict[str, float], float]:
        """One take of step k over h; return arrivals and the wait for the last answer."""

    def step(self, barrier: Barrier, request: StepRequest) -> StepTaken:
        arrivals, wait = self.take(barrier, request.k, request.t, request.h, request.mode,
                                   times=request.times, meanwhile=request.record)
        return StepTaken(request.h, arrivals, wait)
