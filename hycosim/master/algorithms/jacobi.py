"""Jacobi: every node due at T_k steps at once, on the inputs routed at T_k (the paper's scheme)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from hycosim.master.algorithms.interface import Barrier, Coupling, Inputs, StepRequest, StepTaken


class Jacobi(Coupling):
    """One release for every node due at point k; the nodes integrate in parallel."""

    def step(self, barrier: Barrier, request: StepRequest) -> StepTaken:
        # Coupling.step's, without its keywords: the step of every plain run.
        began = time.perf_counter()
        arrivals = barrier.exchange(None, request.k, request.t, request.h, request.mode, times=request.times,
                                    meanwhile=request.record)
        return StepTaken(request.h, arrivals, time.perf_counter() - began)

    def take(self, barrier: Barrier, k: int, t: float, h: float, mode: str, *,
             times: list[float] | None = None, meanwhile: Callable[[], None] | None = None,
             inputs: Inputs | None = None, slopes: dict[str, Any] | None = None) -> tuple[dict[str, float], float]:
        began = time.perf_counter()
        arrivals = barrier.exchange(None, k, t, h, mode, times=times, inputs=inputs, slopes=slopes,
                                    meanwhile=meanwhile)
        return arrivals, time.perf_counter() - began
