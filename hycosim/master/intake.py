"""Checking frames that arrive from nodes before they reach the barrier.

Anything malformed (random bytes, wrong types, unknown ports, a step already past, a
sender whose UID does not own the key it wrote on) is dropped, counted by reason and
logged (boundedly: core.drops); the run goes on. Nothing a payload holds can raise
anything but :class:`Dropped` here.

A value that is NaN or infinite is no malformed frame (a diverging model gives one), so it
is routed like any other; but the first one on each port is noted, with its step and time,
because it poisons every value that depends on it from then on and a user should hear of it.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Annotated, Any, Literal

import msgpack
import msgspec
import structlog

from hycosim.core import frames
from hycosim.core.schema import Node, PortType, array_misfit, wire_types
from hycosim.core.drops import DropLog


def port_mismatch(spec: Node, theirs: Any) -> str | None:
    """How the ports a node's HELLO lists (``theirs``, off the wire) differ from its entry in
    the server's project file, in words; None when they agree or the node listed none."""
    ours = spec.wire_ports()
    if theirs is None or theirs == ours:
        return None
    if type(theirs) is not dict:
        theirs = {}
    differ = []
    for kind in ("input", "output"):
        given = theirs.get(kind)
        if given != ours[kind]:
            shown = ", ".join(frames.short(g) if type(g) is not str else g[:64] for g in given[:32]) \
                if type(given) is list else ""
            differ.append(f"its {kind}s are {shown or 'none'}, the server's {', '.join(ours[kind]) or 'none'}")
    return "; ".join(differ) or None  # other keys beside the two lists are no concern


_NUM = (int, float)


def _real_outputs(uid: int, count: int) -> msgspec.msgpack.Decoder:
    """The decoder of an OUTPUTS frame from a stepping node whose ``count`` outputs are all real
    scalars, which checks in C what it can: the version, the kind and the node's UID as
    themselves, a step in range, then a time and ``count`` values, ints and floats as msgpack
    gives them (a bool or anything else is no such frame). Decoded untyped and checked in
    Python, an answer ran twice the bytecode, which a run pays cold (benchmarks/FINDINGS.md,
    2026-12-04, seventh entry)."""
    return msgspec.msgpack.Decoder(tuple[
        Literal[frames.VERSION], Literal[frames.OUTPUTS], Literal[uid],  # type: ignore[valid-type]
        Annotated[int, msgspec.Meta(ge=0, lt=frames.MAX_STEP)], int | float,
        Annotated[list[int | float], msgspec.Meta(min_length=count, max_length=count)]])


class Dropped(Exception):
    """A frame that is not accepted: a short reason (counted) and a detail (logged)."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


class Intake:
    """The judge of what nodes send: decodes and checks each frame written on a node's ``up`` key
    against the project (its UID, its ports' number and types), and counts and logs what it drops."""

    def __init__(self, nodes: list[Node]):
        self._nodes = {n.nodeName: n for n in nodes}
        self._ports = {n.nodeName: [p.name for p in n.output] for n in nodes}
        self._types = {n.nodeName: [wire_types(p) for p in n.output] for n in nodes}
        # Array outputs, (index, port): checked element by element after the plain pass.
        self._arrays = {n.nodeName: [(i, p) for i, p in enumerate(n.output) if p.shape is not None] for n in nodes}
        # Nodes whose outputs are all scalar numbers: one sum tells whether their values, typed
        # by the node's runtime in process, are all finite (check_direct).
        self._summable = {n.nodeName for n in nodes if all(
            p.shape is None and p.type in (PortType.REAL, PortType.INTEGER, PortType.BOOLEAN) for p in n.output)}
        self._uids = {n.nodeName: n.UID for n in nodes if not n.asynchronous}
        # Stepping nodes whose outputs are all scalar numbers: their types, checked in one pass,
        # and one sum for whether all are finite (plain_outputs).
        self._scalar_types = {n.nodeName: self._types[n.nodeName] for n in nodes if n.nodeName in self._summable}
        # Stepping nodes whose outputs are all real scalars: each one's decoder (_real_outputs;
        # msgspec takes no literal past 2**63 - 1, which leaves such a UID to msgpack's path).
        self._reals = {n.nodeName: _real_outputs(n.UID, len(n.output)) for n in nodes if n.nodeName in self._uids
                       and n.UID < 1 << 63 and all(p.shape is None and p.type is PortType.REAL for p in n.output)}
        self.non_finite: dict[str, dict[str, float]] = {}  # "node.port" → first {"step", "t"} (or "t")
        self._log = structlog.get_logger("server.intake")
        self.drops = DropLog(self._log)

    @property
    def dropped(self) -> Counter[str]:
        """Dropped frames by reason (exact)."""
        return self.drops.counts

    def drop(self, reason: str, detail: str, step: int, sender: str = "") -> None:
        """Count and log a dropped frame (``reason``, ``detail``) at ``step``, from ``sender`` where
        known."""
        self.drops.drop(reason, detail, step, sender)

    def accept(self, node: str, payload: bytes) -> frames.Frame:
        """Decode and check a frame written on ``up/<node>``; raise Dropped otherwise."""
        spec = self._nodes.get(node)
        if spec is None:
            raise Dropped("unknown sender", f"frame on key of unknown node {frames.short(node)}")
        try:
            frame = frames.decode(payload)
        except frames.FrameError as exc:
            raise Dropped("malformed", f"from {node}: {exc}") from None
        if frame.kind not in (frames.OUTPUTS, frames.SAMPLE, frames.HELLO, frames.END, frames.STATE, frames.BATCH):
            raise Dropped("wrong kind", f"from {node}: a {frames.KIND_NAMES[frame.kind]} frame is not for the server")
        uid = frame.uid
        if uid != spec.UID:
            raise Dropped("not owner", f"frame on {node}'s key carries UID {uid}, {node} owns UID {spec.UID}")
        if frame.kind == frames.HELLO:
            return frame
        if frame.kind == frames.STATE:
            try:
                frames.check_chunk(frame.step, frame.index, frame.count, frame.chunk)
            except frames.FrameError as exc:
                raise Dropped("wrong step", f"from {node}: {exc}") from None
            if spec.asynchronous:
                raise Dropped("wrong kind", f"{node} is asynchronous: it has no state to checkpoint")
            return frame
        number = frame.seq if frame.kind == frames.SAMPLE else frame.step
        if not 0 <= number < frames.MAX_STEP:
            raise Dropped("wrong step", f"from {node}: step or sequence number {number} out of range")
        t = frame.t
        if not math.isfinite(t):
            # An infinite sample time would outrank every later sample (held for ever); NaN breaks the order.
            raise Dropped("wrong type", f"from {node}: time {t!r} is not finite")
        if frame.kind == frames.END:
            # A source never ends a run cleanly (it has no end of its own), but it says that it
            # was stopped or failed; it steps in no batch.
            if spec.asynchronous and (frame.clean or frame.earlier or frame.last is not None):
                raise Dropped("wrong kind", f"{node} is asynchronous: it does not end a run, only fails")
            self._check_batch(node, frame.step, t, frame.earlier, last=frame.last)
            return frame
        if frame.kind == frames.BATCH:
            if spec.asynchronous:
                raise Dropped("wrong kind", f"{node} is asynchronous: it takes no batched steps")
            self._check_batch(node, frame.step, t, frame.earlier, last=frame.values)
            return frame
        # A played asynchronous node also sends OUTPUTS: its word that a point's samples are all sent.
        if (frame.kind == frames.SAMPLE) != spec.asynchronous and not (spec.replay and spec.asynchronous):
            raise Dropped("wrong kind", f"{node} is {'' if spec.asynchronous else 'not '}asynchronous")
        self.check_values(node, None if frame.kind == frames.SAMPLE else frame.step, t, frame.values)
        return frame

    def plain_outputs(self, node: str, payload: bytes, step: int) -> list[Any] | None:
        """The values of ``payload`` if it is an OUTPUTS frame that :meth:`accept` takes from
        stepping ``node`` and that carries ``step``; None for anything else, which the caller
        hands to :meth:`accept` (the one judge of what it is, and of why it is dropped).

        The answer of every node in every macro step comes here first: the same checks as
        decode + accept, in one function, without the named tuple (a tenth of the server's
        CPU a step went to the layers this replaces); a node's whose outputs are all real
        scalars decoded and checked in one call in C (_real_outputs)."""
        reals = self._reals.get(node)
        if reals is not None:
            try:
                _, _, _, k, t, values = reals.decode(payload)
            except Exception:  # garbage, or not this node's OUTPUTS: accept() says what it is
                return None
            if k != step:
                return None
            # The answer of every step: one sum says that the time and every value are finite.
            if math.isfinite(t + sum(values)):
                return values
            return self._checked(node, step, t, values) if math.isfinite(t) else None
        uid = self._uids.get(node)
        try:
            obj = msgpack.unpackb(payload, raw=False, strict_map_key=False)
        except Exception:  # any garbage: accept() says what it is
            return None
        if not (type(obj) is list and len(obj) == 6):
            return None
        version, kind, sender, k, t, values = obj
        if not (type(version) is int and version == frames.VERSION and type(kind) is int and kind == frames.OUTPUTS
                and type(sender) is int and sender == uid and type(k) is int and k == step
                and 0 <= k < frames.MAX_STEP and type(t) in _NUM and math.isfinite(t) and type(values) is list):
            return None
        types = self._scalar_types.get(node)
        if types is not None and len(values) == len(types):
            if frames.first_misfit(values, types) is not None:
                return None
            try:
                if math.isfinite(sum(values)):
                    return values
            except (TypeError, OverflowError):
                pass
        return self._checked(node, step, t, values)

    def _checked(self, node: str, step: int, t: float, values: list[Any]) -> list[Any] | None:
        """``values`` if the whole check takes them (an array, a string, a non-finite value
        to note, an int beyond a float's range: what one sum could not say), else None."""
        try:
            self.check_values(node, step, t, values)
        except Dropped:
            return None
        return values

    def _check_batch(self, node: str, step: int, t: float, earlier: list[Any], last: object) -> None:
        """Dropped unless a batch's outputs (``earlier`` steps', then the ``last`` step's unless
        None) are each one value of its port's type for each output, fewer than MAX_BATCH."""
        if len(earlier) >= frames.MAX_BATCH:
            raise Dropped("wrong step", f"from {node}: {len(earlier) + 1} steps' outputs in one batch, "
                                           f"at most {frames.MAX_BATCH}")
        for values in earlier:
            self.check_values(node, step, t, values)
        if last is not None:
            self.check_values(node, step, t, last)

    def check_values(self, node: str, step: int | None, t: float, values: object) -> None:
        """Raise Dropped unless ``values`` are one value of its port's type (and shape) for each of
        ``node``'s outputs, at ``step`` (None for a sample), time t: an OUTPUTS frame's, a
        sample's, or what an in-process node's direct step returned. The first non-finite value
        on each port is noted."""
        ports = self._ports[node]
        if type(values) is not list:
            raise Dropped("wrong type", f"from {node}: {frames.short(values)} where its outputs' values go")
        if len(values) != len(ports):
            raise Dropped("unknown ports", f"from {node}: {len(values)} values for {len(ports)} outputs")
        # frames.first_misfit's rule, in the same pass as the non-finite check: this runs for
        # every frame, and a second pass cost a tenth more per frame (tests/test_receivers.py
        # holds the two to the same answer).
        for port, value, types in zip(ports, values, self._types[node]):
            if type(value) not in types:
                raise Dropped("wrong type", f"{node}.{port} got {type(value).__name__} {frames.short(value)}")
            if type(value) is float and not math.isfinite(value):
                self._note_non_finite(f"{node}.{port}", step, t, value)
        for i, spec in self._arrays[node]:
            value = values[i]
            wrong = array_misfit(spec, value)
            if wrong is not None:
                raise Dropped("wrong type", f"{node}.{spec.name}: {wrong}")
            for j, x in enumerate(value):
                if type(x) is float and not math.isfinite(x):
                    self._note_non_finite(f"{node}.{spec.name}[{j}]", step, t, x)
                    break

    def check_direct(self, node: str, step: int, t: float, values: list[Any]) -> None:
        """:meth:`check_values` for what an in-process node's direct step returned. Its runtime
        made one value per output, each of its port's type (the conversion a node applies before
        it sends a frame; an FMU's listed step reads buffers of those types, matched to the
        ports when it was built), so where every output is a scalar number one sum says whether
        all are finite, and the values are looked at one by one only when it does not (a
        non-finite value to note, a sum that overflowed, an integer beyond a float's range, a
        value that is no number)."""
        if node in self._summable:
            try:
                if math.isfinite(sum(values)):
                    return
            except (TypeError, OverflowError):
                pass
        self.check_values(node, step, t, values)

    def _note_non_finite(self, label: str, step: int | None, t: float, value: float) -> None:
        if label in self.non_finite:
            return
        first = {"t": t} if step is None else {"step": step, "t": t}
        self.non_finite[label] = first
        self._log.warning("non-finite value", port=label, value=repr(value), **first)
