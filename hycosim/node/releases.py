"""How a node reads a release off the wire: the frame's own fields and its own inputs, not the
other nodes'.

A STEP carries every stepping node's inputs in one message (``down``, docs/wire.md), and a
node acts on its own entry alone. It decodes the frame with msgspec, typed, and leaves each
entry of ``inputs`` and ``slopes`` as the bytes it spans (``msgspec.Raw``): another node's
entry is parsed only as far as skipping it takes (well-formed msgpack, or the frame is refused)
and is never built into Python objects or judged. Decoding every node's inputs had been a
third of a node's Python a step at 8 nodes, and grew with the nodes.

Both ways a node takes a release read it so: :meth:`ReleaseReader.decode` (every frame a node
is sent, then checked by ``frames.check_release``) and :meth:`ReleaseReader.plain` (the flat
path over Zenoh, which gives exactly the STEPs the first way acts on and None for the rest).
The flat path reads ``inputs`` as a struct whose one field is the node's entry: the other
entries are skipped as unknown fields are, and the frame and the node's inputs are decoded and
typed in one call. It takes the releases of the mode the node steps in alone, each naming the
nodes that mode drives as its server names them (:meth:`ReleaseReader.plain_decoder`), so
that a release it passes needs no check of mode: one that switches the mode goes the whole way,
which tells the model.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from typing import Annotated, Any, Literal, Union

import msgpack
import msgspec

from hycosim.core import frames


class StepWire(msgspec.Struct, array_like=True, forbid_unknown_fields=True):
    """A STEP as the wire has it (``frames.Step``'s fields after version and kind), with each
    node's inputs and input slopes left undecoded."""

    version: Literal[frames.VERSION]
    kind: Literal[frames.STEP]
    step: int
    t: int | float
    h: int | float
    mode: str
    inputs: dict[str, msgspec.Raw]
    driven: list[str]
    slopes: dict[str, msgspec.Raw]


_STEP = msgspec.msgpack.Decoder(StepWire)
# What ``frames.check_release`` asks of a release's time and step size, as types msgspec checks
# in C while it decodes: a finite time (NaN fails every bound), a finite step size above zero.
_LARGEST = sys.float_info.max
_FINITE = Union[int, Annotated[float, msgspec.Meta(ge=-_LARGEST, le=_LARGEST)]]
_POSITIVE = Union[Annotated[int, msgspec.Meta(gt=0)], Annotated[float, msgspec.Meta(gt=0, le=_LARGEST)]]
# msgspec's own errors, and RecursionError for nesting deeper than it follows (inside an entry
# it skips too: it must find where the entry ends).
REFUSED = (msgspec.MsgspecError, RecursionError)


def _plain_step(node: str, input_types: tuple[tuple[type, ...], ...], mode: str,
                driven: tuple[str, ...]) -> type[msgspec.Struct]:
    """A STEP as node ``node`` reads it on the flat path in ``mode``: StepWire's fields, with
    ``mode`` that mode and ``driven`` exactly the nodes it drives (``driven``, in the release's
    order), ``inputs`` a struct of one field, this node's entry, typed (its other keys, the other
    nodes' entries, are skipped as a struct's unknown fields are: checked to be well-formed,
    never built), and ``slopes`` a struct whose one field, this node's entry, takes no value: a
    release with input slopes for this node goes the whole way. The field's name is the wire's
    key, which need not be a Python identifier; ``mine`` is its field."""
    mine = msgspec.defstruct("Mine", [("mine", tuple[tuple(Union[types] for types in input_types)])],
                             rename={"mine": node}, gc=False)
    no_slopes = msgspec.defstruct("NoSlopes", [("mine", msgspec.UnsetType, msgspec.UNSET)],
                                  rename={"mine": node}, gc=False)
    return msgspec.defstruct("PlainStep", [
        ("version", Literal[frames.VERSION]), ("kind", Literal[frames.STEP]),
        ("step", Annotated[int, msgspec.Meta(ge=0, lt=frames.MAX_STEP)]), ("t", _FINITE),
        ("h", _POSITIVE), ("mode", Literal[mode]), ("inputs", mine),
        ("driven", tuple[tuple(Literal[n] for n in driven)] if driven else tuple[()]),  # type: ignore[misc]
        ("slopes", no_slopes)], array_like=True, forbid_unknown_fields=True, gc=False)


class ReleaseReader:
    """Releases as node ``node`` reads them; ``input_types`` per input the Python types msgpack
    yields for it (``schema.wire_types``); ``drives``: each mode of the run and the nodes it
    drives, as a release names them (``Project.driven_in``)."""

    def __init__(self, node: str, input_types: tuple[tuple[type, ...], ...],
                 drives: Mapping[str, tuple[str, ...]]):
        self.node = node
        self._input_types, self._drives = input_types, dict(drives)
        # The flat path decodes and types a STEP and the node's inputs in one call in C where
        # every input is a scalar (an array or binary port, which may be a list, goes the whole way).
        self.flat = all(list not in types for types in input_types)
        self._plain: dict[tuple[str, bool], Callable[[bytes], Any]] = {}

    def plain_decoder(self, mode: str | None, driven: bool) -> Callable[[bytes], Any] | None:
        """:meth:`plain` for a node stepping in ``mode`` (``driven``: following its driver
        there), as the decoding call, for the loop that reads every release: it raises REFUSED
        where plain() gives None. None where no release takes the flat path in that state: a
        node whose inputs are not all scalars, a mode the run does not have (before the first
        release, none), or a state the mode's releases would change."""
        if mode is None or not self.flat or mode not in self._drives or (self.node in self._drives[mode]) != driven:
            return None
        key = (mode, driven)
        if key not in self._plain:
            step = _plain_step(self.node, self._input_types, mode, self._drives[mode])
            self._plain[key] = msgspec.msgpack.Decoder(step).decode
        return self._plain[key]

    def decode(self, payload: bytes) -> frames.Frame:
        """``frames.decode`` for this node: a STEP comes with this node's entry of ``inputs``
        and ``slopes`` alone (none where the frame has none); FrameError for anything
        ``frames.decode`` refuses, and for a STEP whose fields are not of their types or whose
        entries are not well-formed msgpack (another node's entry is not looked into further)."""
        try:
            wire = _STEP.decode(payload)
        except REFUSED as exc:
            frame = frames.decode(payload)
            if frame.kind == frames.STEP:  # a STEP in shape, but not in its fields' types
                raise frames.FrameError(f"STEP frame with fields of the wrong types: {frames.short(str(exc))}") \
                    from None
            return frame
        node = self.node
        inputs = {node: _unpack(wire.inputs[node])} if node in wire.inputs else {}
        slopes = {node: _unpack(wire.slopes[node])} if node in wire.slopes else {}
        return frames.Step(wire.step, wire.t, wire.h, wire.mode, inputs, wire.driven, slopes)

    def plain(self, payload: bytes, mode: str | None, driven: bool) -> Any | None:
        """The STEP in ``payload`` (its fields named as StepWire's, this node's inputs as
        ``inputs.mine``) if it is one that :meth:`decode` and ``frames.check_release`` pass for
        this node, with inputs for it and no input slopes, that leaves a node stepping in
        ``mode`` (``driven`` or not) in it; None for anything else, which the caller hands to
        those two (the judges of what it is and of why it is refused)."""
        decode = self.plain_decoder(mode, driven)
        if decode is None:
            return None
        try:
            return decode(payload)
        except REFUSED:
            return None


def _unpack(raw: msgspec.Raw) -> Any:
    """One entry of a release, as ``frames.decode`` would have given it."""
    try:
        return msgpack.unpackb(raw, raw=False, strict_map_key=False)
    except Exception as exc:  # msgpack raises several unrelated types for garbage
        raise frames.FrameError(f"STEP frame with an entry that is not msgpack ({type(exc).__name__})") from None
