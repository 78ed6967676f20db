"""Event localisation: where inside a step a guard started to hold, to within eventTolerance.

A step from t of length h ended where a guard holds that did not at t. The step is taken again,
every node rolled back to t, with lengths bisecting (0, h] until the crossing lies in a window
(lo, hi] no wider than the tolerance, and the run goes on from t + hi, where the guard holds:
the event then switches the mode at a point within the tolerance after the crossing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class Located:
    """A located crossing: it lies in (t + lo, t + hi]; the step was taken ``tries`` times more."""

    lo: float
    hi: float
    tries: int


def bisect_crossing(h: float, tolerance: float, take: Callable[[float], bool]) -> Located:
    """Bisect the step length until the crossing's window is at most ``tolerance`` wide.

    ``take(length)`` rolls back and takes the step again with that length, and says whether the
    guard holds at its end. The guard held after the whole step (``h``). The last step taken
    is always the one of length ``hi``, so the nodes stand where the run goes on from.
    """
    lo, hi, tries, at_hi = 0.0, h, 0, True
    while hi - lo > tolerance:
        mid = 0.5 * (lo + hi)
        tries += 1
        if take(mid):
            hi, at_hi = mid, True
        else:
            lo, at_hi = mid, False
    if not at_hi:
        tries += 1
        take(hi)
    return Located(lo, hi, tries)
