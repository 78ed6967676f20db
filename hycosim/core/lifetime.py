"""Helper processes that end with the process they serve.

A ``ProcessPoolExecutor``'s worker learns of a clean exit from its pool, but one whose parent
is killed (SIGKILL, the OOM killer, a crash in native code) waits on its queue for ever, or
first works through every task already queued: it holds both ends of the queue's pipe, so it
never reads the end of it. A forkserver stays beside such a worker, since the worker holds
the write end of the pipe whose closing tells the forkserver that its parent has gone.
"""

from __future__ import annotations

import os
import threading

from hycosim.core.fd_wait import ready


def end_with(pid: int) -> None:
    """End this process as soon as process ``pid`` ends, however it ends: a pool worker's
    ``initializer``, given the pool owner's ``os.getpid()``. Watches a pidfd in a daemon
    thread; where there is none (Linux before 5.3, an old container's seccomp), nothing is
    watched and the process ends as a plain pool's worker does."""
    try:
        watched = os.pidfd_open(pid)
    except ProcessLookupError:
        os._exit(0)
    except OSError:
        return

    def watch() -> None:
        ready(watched)  # readable once the process has ended
        os._exit(0)

    threading.Thread(target=watch, name="end-with", daemon=True).start()
