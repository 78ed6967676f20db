"""The signals that stop a hycosim process: Ctrl-C, and SIGTERM or SIGHUP from a supervisor.

``docker compose down``, systemd and Kubernetes stop a service with SIGTERM, a closed
terminal sends SIGHUP: each is a way out like Ctrl-C, so every process raises
:class:`Stopped` (a KeyboardInterrupt, so that every ``except KeyboardInterrupt`` path
that writes the records and leaves takes it too) and exits with 128 + the signal's number,
as a shell reports a process a signal ended.
"""

from __future__ import annotations

import signal
import threading
from typing import Any

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)

# The exit status of a node whose run the server stopped because it failed elsewhere (the
# server's reason is the node's message); launchers tell it from the node's own failure.
FAILED_ELSEWHERE = 5
# A node whose model cannot be loaded (bad input, as the command line's 2): started again, it fails alike.
NODE_UNLOADABLE = 2


class _Held:
    """Stop signals held off by :func:`hold_stops`. A thread's signal mask would not hold
    them: the kernel gives a process's signal to any thread that does not block it (Zenoh's
    own threads, in a node), and Python then runs the handler in the main thread, held or not
    (a node's END once named the step before the one it had just sent). So the handlers look
    here first. Signal handlers are the process's, and so is this record of them."""

    def __init__(self) -> None:
        self.depth = 0
        self.pending: int | None = None


# The one record: hold_stops and release_stops move its depth, and a loop that sends at every
# step may move it itself, as Outbox.send_outputs does (two calls fewer a step), ending with
# raise_held where a stop came meanwhile.
HELD = _Held()


class Stopped(KeyboardInterrupt):
    """A stop asked for by a signal."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signum)
        self.signum = signum


def signal_of(exc: BaseException) -> int:
    """The signal behind a KeyboardInterrupt (SIGINT for Python's own)."""
    return getattr(exc, "signum", signal.SIGINT)


def name_of(exc: BaseException) -> str:
    """``SIGINT``, ``SIGTERM``…: the name of the signal behind a KeyboardInterrupt."""
    return signal.Signals(signal_of(exc)).name


def describe(exc: BaseException) -> str:
    """``interrupted by Ctrl-C`` or ``stopped by SIGTERM``, for messages and meta.json."""
    return "interrupted by Ctrl-C" if signal_of(exc) == signal.SIGINT else f"stopped by {name_of(exc)}"


def exit_code(exc: BaseException) -> int:
    """128 + the signal's number: 130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP."""
    return 128 + signal_of(exc)


def stop_behind(exc: BaseException) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt (Ctrl-C or a :class:`Stopped`) an exception was raised in the
    handling of, if any: Typer ends every interrupted command with exit status 130, and the
    signal that stopped it is found behind that."""
    seen: set[int] = set()
    link: BaseException | None = exc
    while link is not None and id(link) not in seen:
        if isinstance(link, KeyboardInterrupt):
            return link
        seen.add(id(link))
        link = link.__cause__ or link.__context__
    return None


def raise_on_stop(heard: list[int] | None = None) -> dict[int, Any]:
    """Every stop signal raises :class:`Stopped`: SIGTERM and SIGHUP (a supervisor, a closed
    terminal) as Ctrl-C does. ``heard`` gets each signal's number as it comes: a stop can
    surface as another error (an extension module whose initialisation it interrupted raises
    ImportError), and the signal is still what ended it. Returns the handlers it replaced
    (none off the main thread, where signals cannot be handled)."""
    if threading.current_thread() is not threading.main_thread():
        return {}

    def interrupt(signum: int, frame: Any) -> None:
        if _held_off(signum):
            return
        if heard is not None:
            heard.append(signum)
        raise Stopped(signum)

    return {signum: signal.signal(signum, interrupt) for signum in STOP_SIGNALS}


def _held_off(signum: int) -> bool:
    """In a handler: keep ``signum`` for :func:`release_stops` if stops are held now."""
    if HELD.depth:
        HELD.pending = HELD.pending or signum
        return True
    return False


def hold_stops() -> None:
    """Keep stop signals pending until :func:`release_stops`: what is sent and what the process
    says it sent must not be parted by a stop arriving between them. The handlers keep a signal
    that comes meanwhile (whichever thread the kernel gives it to); no signal mask is changed,
    which would cost two system calls a step and hold nothing more."""
    HELD.depth += 1


def release_stops() -> None:
    """End a :func:`hold_stops`; a stop that came meanwhile is raised now."""
    HELD.depth -= 1
    if HELD.depth == 0 and HELD.pending is not None:
        raise_held()


def raise_held() -> None:
    """Where no stop is held any more (``HELD.depth`` 0): the stop that came while one was, if
    any, handled now as it would have been when it came."""
    if HELD.depth or HELD.pending is None:
        return
    signum, HELD.pending = HELD.pending, None
    handler = signal.getsignal(signum)
    if callable(handler):
        handler(signum, None)


def ignore_stops() -> None:
    """Ignore every stop signal from here on: the process is on its way out, and an
    interruption during its shutdown would leave its records unwritten."""
    if threading.current_thread() is threading.main_thread():
        for signum in STOP_SIGNALS:
            signal.signal(signum, signal.SIG_IGN)


def stop_once() -> None:
    """From here on the first stop signal raises :class:`Stopped`; its handler ignores every
    further one before the interrupted code unwinds."""
    if threading.current_thread() is not threading.main_thread():
        return

    def interrupt(signum: int, frame: Any) -> None:
        if _held_off(signum):
            return
        ignore_stops()
        raise Stopped(signum)

    for signum in STOP_SIGNALS:
        signal.signal(signum, interrupt)
