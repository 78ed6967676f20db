"""Value frames on the wire: msgpack arrays, versioned, one kind per message.

Arrays rather than maps keep frames small and decoding cheap on the hot path. Every
frame starts with ``[VERSION, KIND, ...]``; :func:`decode` rejects anything else with a
:class:`FrameError`, so random bytes never reach the coordinator. What it returns is one
named tuple per kind (:class:`Step`, :class:`Outputs`, ...; ``frame.kind`` on each), whose
fields are named as below: code reads ``step.inputs``, never a position.

Kinds and layouts (after version and kind):

* ``OUTPUTS``  node → server: ``uid, step, t, values`` (values in the node's output order)
* ``SAMPLE``   async node → server: ``uid, seq, t, values``
* ``START``    server → nodes: ``run_id, t0, h, wall_t0, real_time_factor, options``
  (options: ``{"checkpoint": bool}``: save state before each step, for rollback)
* ``STEP``     server → nodes: ``step, t, h, mode, inputs {node: [values]}, driven [nodes], slopes``
  (``slopes {node: [None or [d1, …, dn]]}``: for a node that interpolates its inputs, per input
  its time derivatives at ``t``, orders 1 to MAX_SLOPE_ORDER; None holds it. Empty but for
  iterative coupling with ``interpolate``)
* ``STOP``     server → nodes: ``step, reason`` (``completed`` or ``stopped`` for a run that ended
  as asked, else why it failed: a node reports that failure as its own end)
* ``LIVE``     local only, server: ``node, alive`` (liveliness changes fed into the inbox)
* ``HELLO``    node → server, before its first outputs: ``uid, capabilities`` (``{"rollback": bool,
  "variableStep": bool, "interpolates": bool, "ports": {"input": [...], "output": [...]}}``, the ports as its
  project file has them)
* ``ROLLBACK`` server → nodes: ``step, t``: restore the state saved before that step
* ``REPLAY``   server → one node: ``node, release``: the last START/STEP again, for a node that
  came back after a link cut (it may have missed the release, or the server its outputs)
* ``END``      node → server, in place of its outputs: ``uid, step, t, clean, message, earlier, last``:
  its model ended the simulation at ``t`` (``clean``: an FMU that asked to terminate) or failed
  (the message says how); the server stops the run with the node's own words. ``earlier``:
  inside a batched release (STEPS), the outputs after each of its steps before the one it ended
  in, as a BATCH's (the server records the points they reach); otherwise empty. ``last``: a
  clean end's outputs at ``t`` (the server records them as the run's last point), or None. An
  asynchronous source sends one only to say it failed or was stopped (``clean`` false,
  ``earlier`` empty, ``last`` None)
* ``CHECKPOINT`` server → nodes, just before a release: ``step``: serialise the state at this
  macro-step point (before integrating ``step``) and send it after the step's outputs
* ``STATE``    node → server: ``uid, step, index, count, chunk``: chunk ``index`` of ``count`` of
  the node's serialised state at point ``step`` (states are cut in STATE_CHUNK pieces: a
  frame must fit the low-latency transport, an FMU's state need not)
* ``RESTORE``  server → nodes: ``node, step, t, index, count, chunk, options``: set that node's
  state to a checkpoint's (chunked as STATE) and answer with a HELLO and its outputs at point
  ``step``; options as START's
* ``STEPS``    server → nodes: ``step, times, mode, inputs, driven``: a batched multi-rate release
  of ``len(times) - 1`` base steps from point ``step`` (``times``: the base points' times, the
  last the batch's end). Each node due takes its own steps inside it from these inputs (the
  links make sure they do not change inside it) and answers with one BATCH
* ``BATCH``    node → server: ``uid, step, t, values, earlier``: the answer to a STEPS (labelled
  as OUTPUTS are); ``values`` at the end of the node's last step, ``earlier`` the outputs at
  the end of each of its steps before that, in order
* ``INIT``     server → nodes, between the START's answers and the first release: ``t0, inputs
  {node: [values]}, leave``: the initialisation phase gives each node named in ``inputs`` its
  inputs at t0 as the links carry its peers' start outputs; it takes them without stepping
  (``leave``: and leaves its model's initialisation mode) and answers with its OUTPUTS at step
  0 again (their values now on those inputs)

:func:`decode` checks every field's type (exactly as msgpack yields them: a bool is no
number, a float no step), so that no receiver meets a list where it reads a name or an
int where it iterates. Anything else is a :class:`FrameError` whose message shows at
most a short prefix of what came: a frame may be hostile and large.
"""

from __future__ import annotations

import math
import reprlib
from collections.abc import Callable, Iterable, Mapping
from typing import Any, NamedTuple

import msgpack
import msgspec

VERSION = 2

OUTPUTS = 1
SAMPLE = 2
START = 3
STEP = 4
STOP = 5
LIVE = 6
HELLO = 7
ROLLBACK = 8
REPLAY = 9
END = 10
CHECKPOINT = 11
STATE = 12
RESTORE = 13
STEPS = 14
BATCH = 15
INIT = 16
TUNE = 17

# STOP reasons of a run that ended as asked; any other reason is a failure.
STOP_COMPLETED = "completed"
STOP_STOPPED = "stopped"
CLEAN_STOPS = (STOP_COMPLETED, STOP_STOPPED)

KIND_NAMES = {OUTPUTS: "OUTPUTS", SAMPLE: "SAMPLE", START: "START", STEP: "STEP", STOP: "STOP", LIVE: "LIVE",
              HELLO: "HELLO", ROLLBACK: "ROLLBACK", REPLAY: "REPLAY", END: "END",
              CHECKPOINT: "CHECKPOINT", STATE: "STATE", RESTORE: "RESTORE", STEPS: "STEPS", BATCH: "BATCH",
              INIT: "INIT", TUNE: "TUNE"}

# Steps and sequence numbers stay well inside int64 (the gateway packs them as such).
MAX_STEP = 1 << 62

# A serialised state travels in pieces of at most this many bytes (STATE, RESTORE), and of
# at most MAX_CHUNKS pieces (a state of up to 192 MiB, which bounds what a forged one takes).
STATE_CHUNK = 24 * 1024
MAX_CHUNKS = 1 << 13

# A batched release (STEPS) spans at most this many base steps: its answers carry a value list
# per step of the fastest node, and a frame must fit the low-latency transport.
MAX_BATCH = 100
# The highest time derivative of an input a STEP gives (a cubic over the step).
MAX_SLOPE_ORDER = 3

_NUM = (int, float)  # exact types: msgpack yields bool for booleans, never an int subclass


def _num(v: Any) -> bool:
    return type(v) in _NUM


def _int(v: Any) -> bool:
    return type(v) is int


def _str(v: Any) -> bool:
    return type(v) is str


# Per kind, the type of each field after version and kind. One predicate call per frame on
# the hot path (OUTPUTS at the server, STEP at the nodes).
_SHAPES: dict[int, tuple[int, Callable[[tuple], bool]]] = {
    OUTPUTS: (4, lambda f: type(f[0]) is int and type(f[1]) is int and type(f[2]) in _NUM and type(f[3]) is list),
    SAMPLE: (4, lambda f: type(f[0]) is int and type(f[1]) is int and type(f[2]) in _NUM and type(f[3]) is list),
    START: (6, lambda f: _str(f[0]) and _num(f[1]) and _num(f[2]) and _num(f[3]) and (f[4] is None or _num(f[4]))
            and type(f[5]) is dict),
    STEP: (7, lambda f: type(f[0]) is int and type(f[1]) in _NUM and type(f[2]) in _NUM and type(f[3]) is str
           and type(f[4]) is dict and type(f[5]) is list and type(f[6]) is dict),
    STOP: (2, lambda f: _int(f[0]) and _str(f[1])),
    LIVE: (2, lambda f: _str(f[0]) and type(f[1]) is bool),
    HELLO: (2, lambda f: _int(f[0]) and type(f[1]) is dict),
    ROLLBACK: (2, lambda f: _int(f[0]) and _num(f[1])),
    REPLAY: (2, lambda f: _str(f[0]) and type(f[1]) is bytes),
    END: (7, lambda f: _int(f[0]) and _int(f[1]) and _num(f[2]) and type(f[3]) is bool and _str(f[4])
          and type(f[5]) is list and (f[6] is None or type(f[6]) is list)),
    CHECKPOINT: (1, lambda f: _int(f[0])),
    STATE: (5, lambda f: _int(f[0]) and _int(f[1]) and _int(f[2]) and _int(f[3]) and type(f[4]) is bytes),
    RESTORE: (7, lambda f: _str(f[0]) and _int(f[1]) and _num(f[2]) and _int(f[3]) and _int(f[4])
              and type(f[5]) is bytes and type(f[6]) is dict),
    STEPS: (5, lambda f: type(f[0]) is int and type(f[1]) is list and type(f[2]) is str and type(f[3]) is dict
            and type(f[4]) is list),
    BATCH: (5, lambda f: type(f[0]) is int and type(f[1]) is int and type(f[2]) in _NUM and type(f[3]) is list
            and type(f[4]) is list),
    INIT: (3, lambda f: type(f[0]) in _NUM and type(f[1]) is dict and type(f[2]) is bool),
    TUNE: (4, lambda f: _str(f[0]) and _int(f[1]) and _num(f[2]) and type(f[3]) is dict),
}

_SHORT = reprlib.Repr()
_SHORT.maxstring = _SHORT.maxother = 40
_SHORT.maxlist = _SHORT.maxdict = 4
_SHORT.maxlevel = 2


def short(value: Any) -> str:
    """A repr of at most a few dozen characters, whatever the value's size or depth (for messages)."""
    return _SHORT.repr(value)


class FrameError(ValueError):
    """Bytes that are not a well-formed hycosim frame."""


# One small named tuple per kind, its fields in wire order (after version and kind): code reads
# ``step.inputs``, not a position. ``kind`` is a class attribute, not a field. :func:`decode`
# builds them as cheaply as a plain tuple.


class Outputs(NamedTuple):
    """Node to server: a stepping node's output values (in its output order) at point ``step``, time
    ``t``."""

    kind = OUTPUTS
    uid: int
    step: int
    t: float
    values: list[Any]


class Sample(NamedTuple):
    """Asynchronous node to server: its ``seq``-th sample of output values, stamped ``t``."""

    kind = SAMPLE
    uid: int
    seq: int
    t: float
    values: list[Any]


class Start(NamedTuple):
    """Server to nodes: the run begins at ``t0`` with steps of ``h`` (``options``: whether to save state
    before each step)."""

    kind = START
    run_id: str
    t0: float
    h: float
    wall_t0: float
    real_time_factor: float | None
    options: dict[str, Any]


class Step(NamedTuple):
    """Server to nodes: the release of step ``step`` from ``t`` over ``h`` in ``mode``, each node's
    inputs, the driven nodes, and interpolated inputs' slopes."""

    kind = STEP
    step: int
    t: float
    h: float
    mode: str
    inputs: dict[str, list[Any]]
    driven: list[str]
    slopes: dict[str, Any]


class Stop(NamedTuple):
    """Server to nodes: the run ends at ``step``; ``reason`` is ``completed``, ``stopped``, or why it
    failed."""

    kind = STOP
    step: int
    reason: str


class Live(NamedTuple):
    """Local to the server only: node ``node`` attached (``alive``) or left, from its liveliness
    token."""

    kind = LIVE
    node: str
    alive: bool


class Hello(NamedTuple):
    """Node to server, before its first outputs: its UID and what it can do (rollback, variable steps,
    interpolation, its ports)."""

    kind = HELLO
    uid: int
    capabilities: dict[str, Any]


class Rollback(NamedTuple):
    """Server to nodes: restore the state saved before step ``step`` (at ``t``)."""

    kind = ROLLBACK
    step: int
    t: float


class Replay(NamedTuple):
    """Server to one node: the last START or STEP again, for a node that came back after a link cut."""

    kind = REPLAY
    node: str
    release: Any  # on the wire the release's bytes; a node's check_release gives the frame


class End(NamedTuple):
    """Node to server, in place of its outputs: its model ended the simulation at ``t`` (``clean``) or
    failed (``message``), with the outputs it reached on the way."""

    kind = END
    uid: int
    step: int
    t: float
    clean: bool
    message: str
    earlier: list[list[Any]]
    last: list[Any] | None


class Checkpoint(NamedTuple):
    """Server to nodes, before a release: serialise the state at point ``step`` and send it after the
    step's outputs."""

    kind = CHECKPOINT
    step: int


class State(NamedTuple):
    """Node to server: piece ``index`` of ``count`` of its serialised state at point ``step``."""

    kind = STATE
    uid: int
    step: int
    index: int
    count: int
    chunk: bytes


class Restore(NamedTuple):
    """Server to nodes: set node ``node``'s state to a checkpoint's at ``step`` (in pieces, as STATE)
    and answer with a HELLO and its outputs there."""

    kind = RESTORE
    node: str
    step: int
    t: float
    index: int
    count: int
    chunk: bytes
    options: dict[str, Any]


class Steps(NamedTuple):
    """Server to nodes: a batched multi-rate release of the base steps between ``times``, from point
    ``step``."""

    kind = STEPS
    step: int
    times: list[float]
    mode: str
    inputs: dict[str, list[Any]]
    driven: list[str]


class Batch(NamedTuple):
    """Node to server: the answer to a STEPS, its outputs at the end of its last step and after each one
    before it."""

    kind = BATCH
    uid: int
    step: int
    t: float
    values: list[Any]
    earlier: list[list[Any]]


class Init(NamedTuple):
    """Server to nodes, before the first release: each named node's inputs at ``t0``, taken without
    stepping (``leave``: and leave initialisation mode)."""

    kind = INIT
    t0: float
    inputs: dict[str, list[Any]]
    leave: bool


class Tune(NamedTuple):
    """New values of a node's tunable parameters, taken before its step from point ``step`` (at ``t``)."""

    kind = TUNE
    node: str
    step: int
    t: float
    values: dict[str, Any]


TYPES: dict[int, type] = {OUTPUTS: Outputs, SAMPLE: Sample, START: Start, STEP: Step, STOP: Stop, LIVE: Live,
                          HELLO: Hello, ROLLBACK: Rollback, REPLAY: Replay, END: End, CHECKPOINT: Checkpoint,
                          STATE: State, RESTORE: Restore, STEPS: Steps, BATCH: Batch, INIT: Init, TUNE: Tune}
Frame = (Outputs | Sample | Start | Step | Stop | Live | Hello | Rollback | Replay | End | Checkpoint | State
         | Restore | Steps | Batch | Init | Tune)


_make = tuple.__new__  # a named tuple from the checked fields, without its __new__'s argument handling


# Frames are packed by msgspec, in C, without building a Packer (msgpack.packb makes one, and
# its buffer, at every call; a kept Packer still cost a STEP at 8 nodes four times msgspec's:
# benchmarks/FINDINGS.md, 2026-12-04, the last entry). An Encoder is safe to share between
# threads (frames are packed in Zenoh's threads too). For every value both pack, the bytes are
# msgpack's with use_bin_type; a value msgspec refuses as a type (a subclass of float such as
# NumPy's float64) is packed by msgpack, as before.
_ENCODER = msgspec.msgpack.Encoder()
#: A frame's list packed as :func:`encode` packs it where msgspec takes every value (TypeError
#: where it refuses one, which encode() then packs by msgpack): for a loop that runs every step.
packed = _ENCODER.encode


def encode(kind: int, *fields: Any) -> bytes:
    """Pack one frame of the given kind."""
    frame = [VERSION, kind, *fields]
    try:
        return _ENCODER.encode(frame)
    except TypeError:
        return msgpack.packb(frame, use_bin_type=True)


def decode(payload: bytes) -> Frame:
    """Unpack and shape-check one frame; raise FrameError with the reason otherwise."""
    try:
        obj = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception as exc:  # msgpack raises several unrelated types for garbage (and StackError for depth)
        raise FrameError(f"not msgpack ({type(exc).__name__})") from None
    if type(obj) is not list or len(obj) < 2:
        raise FrameError(f"not a frame array: {short(obj)}")
    version, kind = obj[0], obj[1]
    if type(version) is not int or version != VERSION:
        raise FrameError(f"frame version {short(version)}, expected {VERSION}")
    shape = _SHAPES.get(kind) if type(kind) is int else None
    if shape is None:
        raise FrameError(f"unknown frame kind {short(kind)}")
    fields = obj[2:]
    arity, fits = shape
    if len(fields) != arity:
        raise FrameError(f"{KIND_NAMES[kind]} frame with {len(fields)} fields, expected {arity}")
    if not fits(fields):
        raise FrameError(f"{KIND_NAMES[kind]} frame with fields of the wrong types: {short(fields)}")
    return _make(TYPES[kind], fields)


def check_release(frame: Frame, node: str | None = None, input_types: tuple[tuple[type, ...], ...] | None = None,
                  interpolates: bool = False,
                  input_arrays: tuple[tuple[int, int, tuple[type, ...]], ...] = ()) -> Frame:
    """Return a START, STEP, STEPS or INIT frame a node can act on; raise FrameError otherwise.

    :func:`decode` has checked the field types. Here: times finite, a step size above zero
    (STEPS: 2 to MAX_BATCH + 1 times, each a number, rising), a step number in range, and
    with ``node``, a STEP, STEPS or INIT that gives that node its inputs, exactly
    ``len(input_types)`` of them, each of one of its port's types (``input_types``: per input,
    the Python types msgpack yields for it). A STEP's slopes for that node only if it
    ``interpolates``: one entry per input, None or 1 to MAX_SLOPE_ORDER finite numbers, and
    numbers only for an input that takes floats. ``input_arrays``: (index, size, element types)
    of each array input (whose ``input_types`` is a list): that many elements, each of those
    types. A release anyone on an unsecured network may have written is checked before a node
    acts on it.
    """
    isfinite = math.isfinite
    kind = frame.kind
    if kind == STEP:  # first: the release of every step
        k, t, h, inputs = frame.step, frame.t, frame.h, frame.inputs
        if not (0 <= k < MAX_STEP and isfinite(t) and isfinite(h) and h > 0):
            raise FrameError(f"STEP frame with step {short(k)}, t {short(t)}, h {short(h)}: out of range")
        if node is not None and node in frame.slopes:
            _check_slopes(k, node, frame.slopes[node], input_types, interpolates)
    elif kind == START:
        t0, h, wall0, rt = frame.t0, frame.h, frame.wall_t0, frame.real_time_factor
        if not (isfinite(t0) and isfinite(h) and isfinite(wall0) and h > 0
                and (rt is None or (isfinite(rt) and rt > 0))):
            raise FrameError(f"START frame with times that are not finite or a step size not above 0: "
                             f"{short([t0, h, wall0, rt])}")
        return frame
    elif kind == INIT:
        k, inputs = 0, frame.inputs
        if not isfinite(frame.t0):
            raise FrameError(f"INIT frame at t0 {short(frame.t0)}: not finite")
    elif kind == STEPS:
        k, times, inputs = frame.step, frame.times, frame.inputs
        if not (0 <= k < MAX_STEP and 2 <= len(times) <= MAX_BATCH + 1 and all(type(x) in _NUM for x in times)
                and all(isfinite(x) for x in times) and all(a < b for a, b in zip(times, times[1:]))):
            raise FrameError(f"STEPS frame with step {short(k)}, times {short(times)}: out of range or not rising")
    else:
        raise FrameError(f"a {KIND_NAMES.get(frame.kind, frame.kind)} frame is not a release")
    if node is not None:
        mine = inputs.get(node)
        if type(mine) is not list:
            raise FrameError(f"{KIND_NAMES[frame.kind]} {k} gives node {node!r} no inputs")
        if input_types is not None:
            if len(mine) != len(input_types):
                raise FrameError(f"{KIND_NAMES[frame.kind]} {k} gives node {node!r} {len(mine)} inputs, "
                                 f"it has {len(input_types)}")
            i = first_misfit(mine, input_types)
            if i is not None:
                raise FrameError(f"{KIND_NAMES[frame.kind]} {k} gives node {node!r} a {type(mine[i]).__name__} "
                                 f"for input {i}")
            for i, size, element in input_arrays:
                value = mine[i]
                if len(value) != size or first_misfit(value, [element] * size) is not None:
                    raise FrameError(f"{KIND_NAMES[frame.kind]} {k} gives node {node!r} {short(value)} for "
                                     f"input {i}, an array of {size} elements")
    return frame


def _check_slopes(k: int, node: str, mine: Any, input_types: tuple[tuple[type, ...], ...] | None,
                  interpolates: bool) -> None:
    if not interpolates:
        raise FrameError(f"STEP {k} gives node {node!r} input derivatives; it holds its inputs over a step")
    if type(mine) is not list or (input_types is not None and len(mine) != len(input_types)):
        raise FrameError(f"STEP {k} gives node {node!r} input derivatives that are not one entry per input: "
                         f"{short(mine)}")
    for i, d in enumerate(mine):
        if d is None:
            continue
        if not (type(d) is list and 1 <= len(d) <= MAX_SLOPE_ORDER and all(type(x) in _NUM for x in d)
                and all(math.isfinite(x) for x in d)):
            raise FrameError(f"STEP {k} gives node {node!r} input {i} derivatives that are not 1 to "
                             f"{MAX_SLOPE_ORDER} finite numbers: {short(d)}")
        if input_types is not None and float not in input_types[i]:
            raise FrameError(f"STEP {k} gives node {node!r} derivatives for input {i}, which takes no floats")


def tunable_value(value: Any) -> bool:
    """Whether ``value`` can be a tunable parameter's: a bool, an int of 64 bits, a finite float or a str."""
    t = type(value)
    return (t is bool or t is str or (t is int and -(1 << 63) <= value < (1 << 63))
            or (t is float and math.isfinite(value)))


def check_tune(frame: Tune, node: str, tunable: Mapping[str, Any]) -> Tune:
    """A TUNE frame ``node`` can act on: its step in range, its time finite, and each value one
    of a parameter the node said is tunable (``tunable``: name → its value at the start), of
    that value's type (an int for a float too); FrameError otherwise."""
    k, t, values = frame.step, frame.t, frame.values
    if not (0 <= k < MAX_STEP and math.isfinite(t)) or not values:
        raise FrameError(f"TUNE frame at step {short(k)}, t {short(t)} with {short(values)}: out of range")
    for name, value in values.items():
        if type(name) is not str or name not in tunable:
            raise FrameError(f"TUNE {k} sets {short(name)}, which is no tunable parameter of node {node!r}")
        if not tunable_value(value) or not fits_tunable(value, tunable[name]):
            raise FrameError(f"TUNE {k} sets {name} of node {node!r} to {short(value)}, not a value of its type")
    return frame


def fits_tunable(value: Any, start: Any) -> bool:
    """Whether ``value`` may replace a tunable parameter whose start value is ``start``."""
    if type(start) is float:
        return type(value) in (int, float)
    return type(value) is type(start)


def first_misfit(values: list[Any], types: Iterable[tuple[type, ...]]) -> int | None:
    """The index of the first of ``values`` whose type is none of its port's ``types`` (per port,
    the Python types msgpack yields for it: config.WIRE_TYPES), or None if every one fits.
    The caller has checked that there is one value per port."""
    for i, (value, allowed) in enumerate(zip(values, types)):
        if type(value) not in allowed:
            return i
    return None


def state_chunks(data: bytes) -> list[bytes]:
    """``data`` cut into STATE_CHUNK pieces (one empty piece for no data)."""
    return [data[i:i + STATE_CHUNK] for i in range(0, len(data), STATE_CHUNK)] or [b""]


def check_chunk(step: int, index: int, count: int, chunk: bytes) -> None:
    """FrameError unless ``chunk``, piece ``index`` of ``count`` of a state at ``step``, is in range."""
    if not (0 <= step < MAX_STEP and 0 < count <= MAX_CHUNKS and 0 <= index < count and len(chunk) <= STATE_CHUNK):
        raise FrameError(f"state piece {short(index)} of {short(count)} at step {short(step)}: out of range")


class Chunks:
    """Reassembles one state from its pieces, in any order; a piece of another step or count
    starts over (the sender began another state)."""

    def __init__(self) -> None:
        self.key: tuple[int, int] | None = None
        self._parts: dict[int, bytes] = {}

    def add(self, step: int, index: int, count: int, chunk: bytes) -> bytes | None:
        """Keep a piece (checked by :func:`check_chunk`); return the whole state once complete."""
        if self.key != (step, count):
            self.key, self._parts = (step, count), {}
        self._parts[index] = chunk
        if len(self._parts) < count:
            return None
        data = b"".join(self._parts[i] for i in range(count))
        self.key, self._parts = None, {}
        return data


def largest_values(named: Iterable[tuple[str, Any]], count: int = 3) -> str:
    """``name (N bytes), ...`` for the ``count`` values that take most room in a frame."""
    sizes = sorted(((len(msgpack.packb(v, use_bin_type=True)), name) for name, v in named), reverse=True)
    return ", ".join(f"{name} ({size} bytes)" for size, name in sizes[:count]) or "-"
