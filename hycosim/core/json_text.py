"""JSON from the network or from a user's file, read so that nothing but ValueError escapes."""

from __future__ import annotations

import json
from typing import Any


def loads(data: bytes | str) -> Any:
    """``data`` read as JSON; ValueError (a JSONDecodeError or UnicodeDecodeError, or one saying
    so for nesting) for anything that is not JSON text. Python's decoder recurses once per level
    and raises RecursionError past about a thousand: a few kilobytes of ``[`` would otherwise get
    through every ``except ValueError`` of a reader."""
    try:
        return json.loads(data)
    except RecursionError:
        raise ValueError("nested too deeply to read") from None
