"""Waking the pages' feeds when a source has more to show.

A source (a live run's feed, a finished run's reader) changes in threads of its own; each
page's feed is a coroutine on the web server's event loop. Rather than look for a newer view
on a timer (fifty wake-ups a second per page, on cores a fast run may fill), the feed sleeps
until the source wakes it.
"""

from __future__ import annotations

import asyncio
import threading


class Watchers:
    """The feeds waiting on one source: :meth:`add` on the event loop, :meth:`notify` from any thread."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._events: dict[asyncio.Event, asyncio.AbstractEventLoop] = {}

    def add(self) -> asyncio.Event:
        """An event set whenever the source changes (call it on the loop that awaits it)."""
        event = asyncio.Event()
        with self._lock:
            self._events[event] = asyncio.get_running_loop()
        return event

    def remove(self, event: asyncio.Event) -> None:
        """Stop waking ``event`` (its page's feed ended)."""
        with self._lock:
            self._events.pop(event, None)

    def notify(self) -> None:
        """Wake every waiting feed on its own event loop; a loop already closed is passed over."""
        with self._lock:
            waiting = list(self._events.items())
        for event, loop in waiting:
            try:
                loop.call_soon_threadsafe(event.set)
            except RuntimeError:
                pass  # its loop has closed: the server is stopping
