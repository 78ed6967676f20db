"""Value frames on the wire: msgpack arrays, versioned, one kind per message.

Arrays rather than maps keep frames small and decoding cheap on the hot path. Every
frame starts with ``[VERSION, KIND, ...]``; :func:`decode` rejects anything else with a
:class:`FrameError`, so random bytes never reach the coordinator.

Kinds and layouts (after version and kind):

* ``OUTPUTS``  node → server: ``uid, step, t, values`` (values in the node's output order)
* ``SAMPLE``   async node → server: ``uid, seq, t, values``
* ``START``    server → nodes: ``run_id, t0, H, wall_t0, real_time_factor, options``
  (options: ``{"checkpoint": bool}``: save state before each step, for rollback)
* ``STEP``     server → nodes: ``step, t, H, mode, inputs {node: [values]}, driven [nodes]``
* ``STOP``     server → nodes: ``step, reason`` (``completed`` or ``stopped`` for a run that ended
  as asked, else why it failed: a node reports that failure as its own end)
* ``LIVE``     local only, server: ``node, alive`` (liveliness changes fed into the inbox)
* ``HELLO``    node → server, before its first outputs: ``uid, capabilities`` (``{"rollback": bool,
  "ports": {"input": [...], "output": [...]}}``, the ports as its project file has them)
* ``ROLLBACK`` server → nodes: ``step, t``: restore the state saved before that step
* ``REPLAY``   server → one node: ``node, release``: the last START/STEP again, for a node that
  came back after a link cut (it may have missed the release, or the server its outputs)
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, NamedTuple

import msgpack

VERSION = 1

OUTPUTS = 1
SAMPLE = 2
START = 3
STEP = 4
STOP = 5
LIVE = 6
HELLO = 7
ROLLBACK = 8
REPLAY = 9

# STOP reasons of a run that ended as asked; any other reason is a failure.
STOP_COMPLETED = "completed"
STOP_STOPPED = "stopped"
CLEAN_STOPS = (STOP_COMPLETED, STOP_STOPPED)

_ARITY = {OUTPUTS: 4, SAMPLE: 4, START: 6, STEP: 6, STOP: 2, LIVE: 2, HELLO: 2, ROLLBACK: 2, REPLAY: 2}


class FrameError(ValueError):
    """Bytes that are not a well-formed hycosim frame."""


class Frame(NamedTuple):
    """One decoded frame (a named tuple: decoded for every message, it must be cheap to make)."""

    kind: int
    fields: tuple[Any, ...]


def encode(kind: int, *fields: Any) -> bytes:
    """Pack one frame of the given kind."""
    return msgpack.packb([VERSION, kind, *fields], use_bin_type=True)


def decode(payload: bytes) -> Frame:
    """Unpack and shape-check one frame; raise FrameError with the reason otherwise."""
    try:
        obj = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception as exc:  # msgpack raises several unrelated types for garbage
        raise FrameError(f"not msgpack ({type(exc).__name__})") from None
    if not isinstance(obj, list) or len(obj) < 2:
        raise FrameError("not a frame array")
    version, kind = obj[0], obj[1]
    if version != VERSION:
        raise FrameError(f"frame version {version!r}, expected {VERSION}")
    if kind not in _ARITY:
        raise FrameError(f"unknown frame kind {kind!r}")
    fields = tuple(obj[2:])
    if len(fields) != _ARITY[kind]:
        raise FrameError(f"frame kind {kind} has {len(fields)} fields, expected {_ARITY[kind]}")
    return Frame(kind, fields)


_NUMBER = (int, float)


def _is_number(value: Any) -> bool:
    return isinstance(value, _NUMBER) and not isinstance(value, bool)


def check_release(frame: Frame, node: str | None = None) -> Frame:
    """Return a START or STEP frame whose fields have the types a node reads; raise FrameError otherwise.

    :func:`decode` checks only the shape; a node (or the gateway) reading a release that
    anyone on an unsecured network may have written checks the types before it acts.
    With ``node``, a STEP's inputs for that node, if any, must be a list.
    """
    f = frame.fields
    if frame.kind == START:
        ok = (isinstance(f[0], str) and _is_number(f[1]) and _is_number(f[2]) and _is_number(f[3])
              and (f[4] is None or _is_number(f[4])) and isinstance(f[5], dict))
    elif frame.kind == STEP:
        ok = (type(f[0]) is int and _is_number(f[1]) and _is_number(f[2]) and isinstance(f[3], str)
              and isinstance(f[4], dict) and isinstance(f[5], list)
              and (node is None or isinstance(f[4].get(node, []), list)))
    else:
        raise FrameError(f"frame kind {frame.kind} is not a release")
    if not ok:
        raise FrameError(f"{'START' if frame.kind == START else 'STEP'} frame with fields of the wrong types")
    return frame


def largest_values(named: Iterable[tuple[str, Any]], count: int = 3) -> str:
    """``name (N bytes), ...`` for the ``count`` values that take most room in a frame."""
    sizes = sorted(((len(msgpack.packb(v, use_bin_type=True)), name) for name, v in named), reverse=True)
    return ", ".join(f"{name} ({size} bytes)" for size, name in sizes[:count]) or "-"
