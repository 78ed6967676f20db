"""What a node sends the server: its outputs as the wire's types, and its END (the model
ended the run, failed, or the node was stopped), waiting for the STOP that says it was read."""

from __future__ import annotations

import signal
import socket
import time
from collections.abc import Callable
from typing import Any

from hycosim.core import frames, signals
from hycosim.core.schema import CoSimulation, Node as NodeSpec, Port, PortType
from hycosim.node.interface import AsyncSource, Node
from hycosim.node.receiving import NodeRunError, Receiver
from hycosim.transport.session import FrameTooLarge

_COERCE = {
    PortType.REAL: float,
    PortType.INTEGER: int,
    PortType.BOOLEAN: bool,
    PortType.STRING: str,
    PortType.BINARY: bytes,
}

# How long a node a supervisor stops (SIGTERM, SIGHUP) waits for the server to read its END:
# well inside the 10 s a supervisor (docker, systemd) gives before it kills.
STOPPED_WAIT = 2.0


def coerce(port: Port) -> Callable[[Any], Any]:
    """How a model's value for ``port`` becomes its wire value: an array's, element by element,
    into a list of its shape's size (ValueError otherwise)."""
    one = _COERCE[port.type]
    if port.shape is None:
        return one
    import numpy  # only for array ports: a scalar Python node starts without it (a tenth of a second)

    size = port.size

    def array(value: Any) -> list[Any]:
        if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
            raise ValueError(f"{type(value).__name__} {str(value)[:40]!r} for array port {port.name!r} "
                             f"of shape {list(port.shape)}")
        # numpy flattens row-major whatever the model gives: a numpy array, a list, nested lists.
        flat = numpy.asarray(value).ravel().tolist()
        if len(flat) != size:
            raise ValueError(f"{len(flat)} values for array port {port.name!r} of shape {list(port.shape)} "
                             f"({size} elements)")
        return [one(x) for x in flat]
    return array


def start_feedthrough(impl: Node | AsyncSource, spec: NodeSpec) -> dict[str, list[str]]:
    """The model's start_feedthrough within the node's ports, for the server's initialisation."""
    if not isinstance(impl, Node):
        return {}
    ins, outs = set(spec.input_names()), set(spec.output_names())
    return {out: [i for i in reads if i in ins] for out, reads in impl.start_feedthrough.items()
            if out in outs and any(i in ins for i in reads)}


class Outbox:
    """Frames from node ``spec`` to the server over the receiver's link. ``steps``: the last
    step whose outputs were sent."""

    def __init__(self, spec: NodeSpec, cosim: CoSimulation, receiver: Receiver, log: Any):
        self.spec, self.name, self.uid, self.cosim, self.receiver, self.log = (
            spec, spec.nodeName, spec.UID, cosim, receiver, log)
        self.ports = [(p.name, coerce(p)) for p in spec.output]
        self.steps = 0

    def hello(self, impl: Node | AsyncSource, rollback: bool, restart: bool = False) -> bytes:
        """The node's HELLO: what it can take part in, its ports, its host."""
        stepping = isinstance(impl, Node)
        return frames.encode(frames.HELLO, self.uid, {
            "rollback": rollback, "serialize": stepping and impl.can_serialize,
            "variableStep": stepping and impl.can_vary_step, "restart": restart, "batches": stepping,
            "interpolates": self.receiver.interpolating, "startFeedthrough": start_feedthrough(impl, self.spec),
            "tunable": self.receiver.tunable,
            "initializationMode": stepping and impl.holds_initialization,
            "ports": self.spec.wire_ports(), "host": socket.gethostname()[:64]})

    def pack(self, values: dict[str, Any]) -> list[Any]:
        """The model's outputs as the wire carries them, in the ports' order."""
        packed = []
        for port, convert in self.ports:
            if port not in values:
                raise NodeRunError(f"node {self.name!r}: its model returned no value for output {port!r}")
            try:
                packed.append(convert(values[port]))
            except (TypeError, ValueError, OverflowError) as exc:
                raise NodeRunError(f"node {self.name!r}: output {port!r}: {exc}") from None
        return packed

    def send(self, payload: bytes) -> None:
        """Publish one frame; one too large for the link stops the node, naming its largest outputs."""
        try:
            self.receiver.link.send(payload)
        except FrameTooLarge as exc:
            raise self.too_large(payload, exc) from None

    def too_large(self, payload: bytes, exc: FrameTooLarge) -> NodeRunError:
        """The error for a frame the link cannot carry, naming the node's largest outputs."""
        frame = frames.decode(payload)
        values = frame.values if frame.kind in (frames.OUTPUTS, frames.SAMPLE, frames.BATCH) else []
        largest = frames.largest_values(zip((port for port, _ in self.ports), values))
        return NodeRunError(f"node {self.name!r}: its outputs at step {self.steps} are {exc}; largest: {largest}")

    def send_outputs(self, payload: bytes, step: int) -> None:
        """Send outputs and count them as this node's last ``step`` with no stop signal between:
        a SIGTERM that came after the send and before the count had the node's END name the
        step before the one the server had (once, in a loaded make test)."""
        held = signals.HELD
        held.depth += 1  # hold_stops() and release_stops(), inline: this runs at every step
        try:
            try:  # send()'s body
                self.receiver.link.send(payload)
            except FrameTooLarge as exc:
                raise self.too_large(payload, exc) from None
            self.steps = step
        finally:
            held.depth -= 1
            if held.pending is not None:
                signals.raise_held()

    def _await_stop(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            frame = self.receiver.next_frame(left)
            if frame is None or frame.kind == frames.STOP:
                break

    def end(self, step: int, t: float, clean: bool, message: str, earlier: list[list[Any]] | None = None,
            last: list[Any] | None = None) -> None:
        """Tell the server this node's model ended the run (``clean``) or failed, in place of its
        outputs for ``step`` (``earlier``: those of its steps inside a batch before that;
        ``last``: its outputs at ``t``, where the model ended, if it could give them), and
        wait for the server's STOP (so that it hears this first, not that the node's token
        went). A failure is raised as this node's own."""
        message = message[:2000]
        try:
            self.send(frames.encode(frames.END, self.uid, step, t, clean, message, earlier or [], last))
            # In process the master reads the END once this call returns: there is nothing to wait for.
            self._await_stop(min(10.0, self.cosim.stepTimeout) if self.receiver.pulls else 0.0)
        except NodeRunError:
            pass  # the server is gone: the node's own message says enough
        if not clean:
            raise NodeRunError(message)
        self.log.info("ended the simulation", step=step, t=t, message=message)

    def say_stopped(self, exc: BaseException, asynchronous: bool) -> None:
        """A node stopped by SIGTERM or SIGHUP (its supervisor) tells the server, which then names it
        rather than a lost token. Not on Ctrl-C: a terminal's reaches the server too, which
        reports its own interruption."""
        if signals.signal_of(exc) == signal.SIGINT:
            return
        # A source knows no step (the server adds the run's).
        said = (f"node {self.name!r} (an asynchronous source) {signals.describe(exc)}" if asynchronous else
                f"node {self.name!r} {signals.describe(exc)} after step {self.steps}")
        try:
            self.send(frames.encode(frames.END, self.uid, self.steps + 1, 0.0, False, said, [], None))
            # The token goes as this process leaves, and the server can learn that before it
            # reads the END (it did on a loaded machine, and named a lost token): wait for its
            # STOP, which says it has read it. A second signal ends the wait.
            self._await_stop(STOPPED_WAIT)
        except Exception:  # on its way out: the token's loss still tells the server
            pass
