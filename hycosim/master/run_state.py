"""What the master's parts share about a run: where the loop is (Point, Seen), how it ends
(RunError, ModelEnded, Recover, Ending), what it reports (Progress, Rate) and who holds it at
a point (PointGate)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

from hycosim.core import frames
from hycosim.core.schema import FREE_MODE
from hycosim.master.routing import OutputView

RECENT_KEPT = 4096  # the latest points kept for the status answers


class RunError(RuntimeError):
    """A run that cannot go on; the message names the node and the step."""


class Recover(Exception):
    """A node's process was started again mid-run: the run goes back to its last checkpoint."""

    def __init__(self, node: str, step: int, cause: str):
        super().__init__(cause)
        self.node, self.step, self.cause = node, step, cause


@dataclass
class PendingCheckpoint:
    """A checkpoint asked for at point ``step``: the server's state then, and the nodes' as they come."""

    step: int
    server: dict[str, Any]
    states: dict[str, bytes] = field(default_factory=dict)
    chunks: dict[str, frames.Chunks] = field(default_factory=dict)


class ModelEnded(Exception):
    """A node's model ended the simulation (an FMU that asked to terminate): the run's records
    end at the last macro-step point every node reached, then the point where it ended."""


@dataclass(slots=True)
class Point:
    """Where the loop is: point k at time t, the j-th of the grid origin + j·H (a located event
    starts a new grid at its time), and how the step to it went."""

    k: int
    t: float
    origin: float
    j: int
    localised: dict[str, Any]  # the located event that ended the step to it
    arrivals: dict[str, float]  # each node's answer, seconds after its release
    wait: float  # from the release to the last answer
    takes: int = 1  # of the step to it (iterated or size-controlled)


@dataclass(slots=True)
class Seen:
    """Point k as the loop saw it before stepping from it: what its record holds."""

    mode: str
    outputs: dict[str, list[Any]]
    view: OutputView
    ages: dict[str, float | None]
    lateness: float | None
    holder: str  # the node whose answer came last
    stepped: list[str] | None  # a multi-rate run's nodes stepped from it


# A node's own words about why it ended or failed are shown and recorded up to this length.
MESSAGE_MAX = 2000


@dataclass
class Progress:
    """What the server reports while running (read by ``hycosim run``'s progress bar)."""

    step: int = 0
    t: float = 0.0
    mode: str = FREE_MODE
    steps_per_s: float = 0.0
    attached: list[str] = field(default_factory=list)
    lateness_s: float | None = None  # a paced run's, at the last point


@dataclass
class Ending:
    """A node's model that ended the run: ``by`` (its node, step, t and words) once one did.
    While the release it ended in is gathered: the nodes that ended in it (``inside``) and the
    release's arrivals (the others' outputs are gathered first; inside a batched release the
    points the ended steps before reached are recorded), and the ended node's outputs at its
    end (``values``, its END's)."""

    by: dict[str, Any] | None = None
    inside: set[str] = field(default_factory=set)
    arrivals: dict[str, float] = field(default_factory=dict)
    values: list[Any] | None = None


class Rate:
    """The run's steps a second since the loop began, handed with the progress to
    ``on_progress`` at most every ``every`` seconds and at the end."""

    def __init__(self, every: float, on_progress: Callable[[Progress], None] | None):
        self.every, self.on_progress = every, on_progress
        self.began, self.k0, self.reported = 0.0, 0, 0.0

    def begin(self, k: int) -> None:
        """The loop begins at point ``k``: the rate counts from here."""
        self.began, self.k0 = time.perf_counter(), k

    def point(self, progress: Progress, k: int, now: float) -> None:
        """Point ``k`` reached at ``now`` (perf_counter): hand ``progress`` with the rate to
        ``on_progress`` where ``every`` seconds have passed since it was last told."""
        if self.on_progress is not None and now - self.reported >= self.every:
            self.reported = now
            progress.steps_per_s = (k - self.k0) / (now - self.began) if now > self.began else 0.0
            self.on_progress(progress)

    def end(self, progress: Progress, k: int) -> float | None:
        """The rate over the whole loop (None if no time passed), reported once more."""
        elapsed = time.perf_counter() - self.began
        rate = (k - self.k0) / elapsed if elapsed > 0 else None
        if self.on_progress is not None:
            progress.steps_per_s = rate or 0.0
            self.on_progress(progress)
        return rate


class PointGate(Protocol):
    """When the step from a macro-step point is taken (the run's points other than the last)."""

    def hold(self, step: int, t: float) -> None:
        """Return once the step from point ``step`` (at ``t``) may be taken. The relay is at
        the point meanwhile: its outputs gathered and its inputs routed, nothing stepping."""


class OpenGate(PointGate):
    """Every step at once: a run from the command line."""

    def hold(self, step: int, t: float) -> None:
        return None


OPEN = OpenGate()
