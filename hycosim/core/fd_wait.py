"""Waiting on one file descriptor, whatever its number.

``select.select`` refuses a descriptor of 1024 or more (FD_SETSIZE), which a process with many
files open hands out: a Dask worker that has run many runs, a Python caller holding sockets.
``poll`` has no such limit.
"""

from __future__ import annotations

import math
import select


def ready(fd: int, *, write: bool = False, timeout: float | None = None) -> bool:
    """Whether ``fd`` can be read (or, ``write``, written) within ``timeout`` seconds (None:
    however long it takes). A closed other end counts as ready: the read or write then says so."""
    poller = select.poll()
    poller.register(fd, select.POLLOUT if write else select.POLLIN)
    ms = None if timeout is None else max(0, math.ceil(timeout * 1000))
    return bool(poller.poll(ms))
