"""The process's heap while a run steps: what was alive before it left out of the cyclic
garbage collector's scans.

A server or node process holds some fifty thousand objects from its imports and set-up
(modules, the project's models, Zenoh's, pydantic's). A run's own objects are mostly freed by
reference counting, but the few that live a while (rows waiting for a flush, the points the
status answer keeps) set off collections all the same, and each full collection walked the
set-up's objects too: a pause of 16–25 ms in a server's run at two nodes, in which no release
went out. Frozen (:func:`gc.freeze`), the set-up's objects are not walked, and a full
collection walks the run's own objects alone (none came in a server's run of 60,000 steps at
two nodes, against one of 16 ms unfrozen). By the collector's rule (it waits until a quarter
as many objects as it would walk have come of age) it comes more often then, so over a very
long run its time is about the same either way; its pauses are what is shorter. The
objects are given back to the collector when the run is over, so that a process that runs
again (a Python caller, an ensemble's worker) keeps no garbage of it for ever.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def set_up_frozen() -> Iterator[None]:
    """For the block: every object alive at its start out of the collector's scans; back in
    them after, whatever happened (garbage among them is collected then: no collection first,
    which would cost every process's start a full one)."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()
