"""Hints for names that are not known: the closest known one, for a misspelt name."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def did_you_mean(unknown: Iterable[str], known: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` naming the closest known name to each unknown one, or ``""``."""
    known = list(known)
    guesses = [m for name in unknown for m in difflib.get_close_matches(name, known, n=1)]
    return f"; did you mean {', '.join(map(repr, guesses))}?" if guesses else ""
