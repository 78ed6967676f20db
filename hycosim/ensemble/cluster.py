"""The Dask side of every ensemble (a sweep's runs, the paper's trials): a client of a
``LocalCluster`` of worker processes or of a scheduler by address, and the jobs handed to it,
taken back in the order they end. A job that raises, or whose worker dies, comes back with what
it raised; Ctrl-C (or leaving the loop early) cancels the rest."""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Hashable, Iterator
from contextlib import contextmanager
from typing import Any

from hycosim.ensemble.variants import SweepError


def require_ensemble(what: str = "a sweep") -> None:
    """SweepError naming the extra where Dask or pyarrow is missing."""
    try:
        import dask.distributed  # noqa: F401
        import pyarrow  # noqa: F401
    except ImportError as exc:
        raise SweepError(f"{what} needs the ensemble extra ({exc.name} is missing): "
                         "pip install 'hycosim[ensemble]'") from None


@contextmanager
def dask_client(workers: int | None, scheduler: str | None) -> Iterator[Any]:
    """A client of the scheduler at ``scheduler`` (SweepError if it cannot be reached), or of a
    ``LocalCluster`` of ``workers`` single-threaded processes, closed on leaving (the local
    cluster too)."""
    from dask.distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="20s")
        except OSError as exc:
            raise SweepError(f"--scheduler {scheduler}: cannot reach it ({exc})") from None
        try:
            yield client
        finally:
            client.close()
        return
    # One thread a worker: a run is CPU-bound Python, and a co-simulation's own threads (Zenoh,
    # timers) must not share a worker's GIL with a second run.
    cluster = LocalCluster(n_workers=workers or 1, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=50)
    client = Client(cluster)
    try:
        # Out of the terminal's process group: its Ctrl-C is the caller's to handle (it cancels
        # the jobs, or stops what they started); a worker it reached would only print its own
        # tracebacks over the caller's message.
        try:
            client.run(os.setsid)
        except OSError:  # a worker that leads its group already: only the tracebacks are at stake
            pass
        yield client
    finally:
        client.close()
        cluster.close()


def each_ended(client: Any, fn: Callable[..., Any],
               jobs: list[tuple[Hashable, tuple]]) -> Iterator[tuple[Hashable, Any, BaseException | None]]:
    """Submit ``fn(*args)`` for each ``(tag, args)`` of ``jobs``; yield ``(tag, result, None)``
    or ``(tag, None, what it raised)`` as each ends. Leaving the loop (Ctrl-C included) cancels
    the jobs not yet ended."""
    from dask.distributed import as_completed

    batch = uuid.uuid4().hex[:12]  # keys are the scheduler's, shared with every other client of it
    futures = {client.submit(fn, *args, pure=False, key=f"hycosim-{fn.__name__}-{batch}-{n}"): tag
               for n, (tag, args) in enumerate(jobs)}
    try:
        for future in as_completed(futures):
            tag = futures[future]
            try:
                result = future.result()
            except Exception as exc:  # noqa: BLE001 - a job that raised, or a worker that died: the job's outcome
                yield tag, None, exc
            else:
                yield tag, result, None
    finally:
        client.cancel([f for f in futures if not f.done()])
