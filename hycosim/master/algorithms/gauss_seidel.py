"""Gauss-Seidel: within a macro step the nodes step one after the other, each on the outputs
its predecessors have already advanced to T_k + H."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from hycosim.master.algorithms.interface import Barrier, Coupling, Inputs


class GaussSeidel(Coupling):
    """One release per node in ``barrier.order``; each node's inputs are routed again just
    before its release. Point k's record holds the inputs every node stepped on."""

    def take(self, barrier: Barrier, k: int, t: float, h: float, mode: str, *,
             times: list[float] | None = None, meanwhile: Callable[[], None] | None = None,
             inputs: Inputs | None = None, slopes: dict[str, Any] | None = None) -> tuple[dict[str, float], float]:
        began = time.perf_counter()
        arrivals: dict[str, float] = {}
        try:
            for i, node in enumerate(barrier.order):
                if i > 0:
                    barrier.route_into(node, mode)
                arrivals.update(barrier.exchange([node], k, t, h, mode, since=began))
        finally:
            if meanwhile is not None:
                meanwhile()  # once every node has stepped: the record holds the inputs each stepped on
        return arrivals, time.perf_counter() - began
