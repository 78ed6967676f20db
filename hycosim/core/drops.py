"""Counting and logging what a receiver drops, with the log bounded whatever comes in.

A hostile or broken peer can send frames as fast as the link carries them; one log line
per dropped frame let 40,000 frames of random bytes write 7 MB of log in 5 s. The counts
stay exact (``meta.json`` has them); the log has the first few drops of each reason and
sender in full, then at most one summary line per reason per second.
"""

from __future__ import annotations

import time
from collections import Counter
from typing import Any

FULL_PER_SENDER = 5  # drops logged in full per (reason, sender)
SUMMARY_EVERY_S = 1.0  # at most one summary line per reason this often
_MAX_SENDERS = 256  # (reason, sender) pairs tracked for full logs; senders may be made up by the peer


class DropLog:
    """Exact counts of dropped frames by reason (:attr:`counts`); a bounded log of them."""

    def __init__(self, log: Any, full_per_sender: int = FULL_PER_SENDER, summary_every_s: float = SUMMARY_EVERY_S):
        self.counts: Counter[str] = Counter()
        self._log = log
        self._full_per_sender = full_per_sender
        self._every = summary_every_s
        self._logged: Counter[tuple[str, str]] = Counter()
        self._unlogged: Counter[str] = Counter()  # per reason, since its last log line
        self._last_summary: dict[str, float] = {}

    def drop(self, reason: str, detail: str, step: int, sender: str = "") -> None:
        """Count one dropped frame; log it in full, fold it into a summary, or neither (yet)."""
        self.counts[reason] += 1
        key = (reason, sender)
        logged = self._logged.get(key)
        if logged is not None or len(self._logged) < _MAX_SENDERS:
            if (logged or 0) < self._full_per_sender:
                self._logged[key] = (logged or 0) + 1
                self._log.warning("frame dropped", reason=reason, sender=sender, detail=detail, step=step)
                return
        self._unlogged[reason] += 1
        now = time.monotonic()
        if now - self._last_summary.get(reason, 0.0) >= self._every:
            self._summarise(reason, now, step)

    def _summarise(self, reason: str, now: float, step: int) -> None:
        self._last_summary[reason] = now
        self._log.warning("frames dropped", reason=reason, count=self._unlogged.pop(reason, 0),
                          total=self.counts[reason], step=step)

    def flush(self, step: int) -> None:
        """Log the drops not yet in the log (at the end of a run)."""
        now = time.monotonic()
        for reason in list(self._unlogged):
            self._summarise(reason, now, step)
