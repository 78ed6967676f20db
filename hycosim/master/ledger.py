"""The releases' ledger: which step each node owes, where, and what an answer is to it.

Every release names the step its answers carry (the release point + 1) and the point they are
gathered at: the next point, or later for a node slower than the run's base step (multi-rate),
or the last base point of a batched release (STEPS), where the node answers with one BATCH
holding its outputs after each of its own steps. The ledger keeps that per node and sorts each
answer that comes while a point is gathered: taken, kept for a later point (a slower node that
answered early), the node's END, or refused with the reason the intake counts it under.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

from hycosim.core import frames

# What an answer is to the point being gathered (besides a Refusal).
TAKE = "take"  # the node's outputs for this point
LATER = "later"  # a slower node's outputs for a later point: kept until then
ENDED = "ended"  # the node's END for the step it owes


@dataclass(frozen=True)
class Refusal:
    """An answer the point cannot use: dropped and counted under ``reason``."""

    reason: str
    detail: str


class Ledger:
    """The outstanding step of each stepping node, and the answers kept for later points.

    ``paced``: played asynchronous sources, gathered at every point with no step of their own
    (their word that the point's samples are sent carries the point's own step).
    """

    def __init__(self, stepping: list[str], paced: list[str], rates: dict[str, int]):
        self._label = {n: 0 for n in stepping}  # the step each node's answer carries
        self._due_at = {n: 0 for n in stepping}  # the point it is gathered at
        self._released_at: dict[str, float] = {}  # perf_counter at its release
        self._batch: dict[str, int] = {}  # a batched node: the steps before its last its BATCH holds
        self._early: dict[str, frames.Frame] = {}
        self._paced = frozenset(paced)
        self._rates = rates
        self._one_rate = all(m == 1 for m in rates.values())
        # Each stepping node that owes one OUTPUTS (not a BATCH): (the step it carries, the
        # perf_counter of its release). Read by the barrier for every answer, so kept as it changes.
        self.owes_outputs: dict[str, tuple[int, float]] = {}
        # Each node's outputs after its steps before the last of the batched release being
        # gathered (its BATCH's or END's ``earlier``).
        self.earlier: dict[str, list[list[Any]]] = {}

    def expect_all(self, step: int, released_at: float) -> None:
        """Every stepping node owes its outputs at ``step`` (the START, a restore), one OUTPUTS
        each: no batch and no answer kept from before stands."""
        self._batch.clear()
        for node in self._label:
            self._label[node] = self._due_at[node] = step
            self._released_at[node] = released_at
            self.owes_outputs[node] = (step, released_at)
        self._early.clear()

    def released(self, nodes: list[str], k: int, released_at: float, *, count: int = 1,
                 batched: bool = False, span: int = 1, last_point: float = math.inf) -> None:
        """``nodes`` were released from point k over ``count`` base steps: each owes its outputs,
        labelled k + 1, at the end of its own step (k + its rate, at most ``last_point``). In a
        batched release (``batched``, of up to ``span`` base steps) a node as fast as the batch
        or faster owes one BATCH at its end, with its outputs after each of its steps before."""
        self.earlier.clear()
        label, due_at, batch, rates, owes = self._label, self._due_at, self._batch, self._rates, self.owes_outputs
        if not batched and not batch and self._one_rate:
            # Every node a base step a release, none in a batch (every step of a plain run):
            # each owes the next point's outputs.
            owed, at = (k + 1, released_at), self._released_at
            for n in nodes:
                label[n] = due_at[n] = k + 1
                owes[n], at[n] = owed, released_at
            return
        for n in nodes:
            label[n] = k + 1
            m = rates[n]
            if not batched:
                if batch:
                    batch.pop(n, None)
                due_at[n] = k + 1 if m == 1 else min(k + m, last_point)
                owes[n] = (k + 1, released_at)
            else:
                batch[n] = len(range(0, count, m)) - 1
                due_at[n] = k + count if m <= span else min(k + m, last_point)
                owes.pop(n, None)
            self._released_at[n] = released_at

    def due(self, step: int) -> set[str]:
        """The stepping nodes whose outputs are gathered at point ``step``."""
        return {n for n, at in self._due_at.items() if at == step}

    def label(self, node: str, step: int) -> int:
        """The step ``node``'s answer carries while point ``step`` is gathered."""
        return step if node in self._paced else self._label.get(node, step)

    def since_release(self, node: str, default: float) -> float:
        """Seconds since ``node`` was released (since ``default``, a perf_counter, if never)."""
        return time.perf_counter() - self._released_at.get(node, default)

    def sort(self, node: str, frame: frames.Frame, step: int, pending: set[str]) -> str | Refusal:
        """What ``frame`` (a node's OUTPUTS, BATCH or END) is while point ``step`` is gathered
        from ``pending``: :data:`TAKE`, :data:`LATER`, :data:`ENDED`, or a :class:`Refusal`."""
        label = self.label(node, step)
        if frame.step != label:
            return Refusal("step already past" if frame.step < label else "wrong step",
                           f"{node} sent step {frame.step} while collecting {step}")
        if frame.kind == frames.END:
            return ENDED
        batched = self._batch.get(node)
        if (frame.kind == frames.BATCH) != (batched is not None):
            return Refusal("wrong kind", f"{node} sent a {frames.KIND_NAMES[frame.kind]} frame for step "
                           f"{frame.step}, which it was released for {'in' if batched is None else 'as'} a batch")
        if batched is not None and len(frame.earlier) != batched:
            return Refusal("wrong step", f"{node} sent the outputs of {len(frame.earlier) + 1} steps for "
                           f"a batch of {batched + 1} of its steps")
        if node in pending:
            return TAKE
        if node in self._paced or node in self._early or self._due_at.get(node, step) <= step:
            return Refusal("duplicate", f"{node} sent step {frame.step} twice")
        return LATER

    def keep(self, node: str, frame: frames.Frame) -> None:
        """Keep a slower node's answer (sorted :data:`LATER`) for the point it is due at."""
        self._early[node] = frame

    def kept_for(self, pending: set[str]) -> list[tuple[str, frames.Frame]]:
        """The answers kept earlier of the ``pending`` nodes, handed over (in node order)."""
        if not self._early:
            return []
        return [(node, self._early.pop(node)) for node in sorted(pending & self._early.keys())]
