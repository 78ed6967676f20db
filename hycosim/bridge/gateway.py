"""The relay's TCP gateway: bridge FMUs attach here and join the same barrier as Zenoh nodes.

The paper's server "can also transmit FMU data": a tool that can only import FMUs loads
a generated bridge FMU, which connects here (framing in ``bridge/gateway_protocol``).
The gateway turns that connection into an ordinary node for the relay. An accepted HELLO
declares the node's liveliness token in the relay's session, so the relay sees it attach
exactly as a Zenoh node, and a second process for the node (over Zenoh or the gateway)
finds the token held and is refused. Each OUTPUTS frame becomes the msgpack frame a Zenoh
node would have published on ``up/<node>`` (put session-locally, so it takes the same
path through intake and barrier), and the server's START/STEP/STOP on ``down`` are
written back to each connection with that node's inputs. A closed connection undeclares
the token: a lost node.
"""

from __future__ import annotations

import math
import socket
import threading
from typing import Callable

import structlog
import zenoh

from hycosim.core import frames
from hycosim.bridge import gateway_protocol as gp
from hycosim.core.schema import WIRE_TYPES, Node, PortType
from hycosim.core.endpoints import Address, listen_family
from hycosim.transport.keys import ProjectKeys
from hycosim.transport.session import token_held

def _to_int(v: float) -> int:
    # NaN and infinities have no integer: a ValueError the reader drops the frame for.
    if not math.isfinite(v):
        raise ValueError(f"{v} for an Integer output")
    return int(round(v))


_FROM_WIRE: dict[PortType, Callable[[float], object]] = {
    PortType.REAL: float,
    PortType.INTEGER: _to_int,
    PortType.BOOLEAN: lambda v: v != 0.0,
}


_MAX_HANDSHAKES = 64


class GatewayError(RuntimeError):
    """The gateway cannot listen where it was told to."""


class _Connection:
    def __init__(self, sock: socket.socket, node: Node, token: zenoh.LivelinessToken | None, rate: int = 1):
        self.sock = sock
        self.node = node
        self.token = token
        self.rate = rate  # the node's step in base steps (a multi-rate run)
        self.lock = threading.Lock()
        # Bridge FMUs carry Real, Integer and Boolean ports, all as f64: no value passes for another.
        self.input_types = tuple(WIRE_TYPES[p.type] if p.type in _FROM_WIRE else () for p in node.input)
        # (STEPs sent, the last one's step k): a bridge FMU counts its own steps, and its outputs
        # after its n-th step answer the n-th release, labelled as a node labels them, k + 1.
        # One tuple, so the reader thread never sees a count of one release and a k of another.
        self.released: tuple[int, int] = (0, -1)

    def releasing(self, k: int) -> None:
        """Count a STEP of step ``k`` about to go to the bridge FMU (before it goes: the answer
        can come at once)."""
        self.released = (self.released[0] + 1, k)

    def label(self, step: int) -> int | None:
        """The hycosim step label of outputs the bridge FMU sent after its ``step``-th step; None
        for a count that answers no release sent (outputs out of turn)."""
        count, k = self.released
        if step != count:
            return None
        return 0 if count == 0 else k + 1

    def send(self, data: bytes) -> None:
        with self.lock:
            self.sock.sendall(data)


def translate_release(payload: bytes, conns: list[_Connection], stop_time: float = math.inf
                      ) -> dict[_Connection, bytes]:
    """The gateway frames a message on ``down`` means for each connection: a START or STOP for
    every one, a STEP for those it releases (in a multi-rate or Gauss-Seidel run, a release
    leaves out the nodes not due), none for a kind that is not for bridge FMUs. Each gets its own
    step size (``rate`` base steps, the last cut at ``stop_time``). FrameError for anything that
    is not a release each bridge FMU it names can act on, whatever the bytes."""
    frame = frames.decode(payload)
    if frame.kind == frames.START:
        start = frames.check_release(frame)
        return {c: gp.start(start.t0, c.rate * start.h) for c in conns}
    if frame.kind == frames.STEP:
        k, t, h, inputs, driven = frame.step, frame.t, frame.h, frame.inputs, frame.driven
        data = {}
        for c in conns:
            if c.node.nodeName not in inputs:
                continue  # not due at this step
            frames.check_release(frame, c.node.nodeName, c.input_types)  # its inputs too: a bridge FMU holds them
            own = h if c.rate == 1 else min(c.rate * h, stop_time - t)
            data[c] = gp.step(k, t, own, c.node.nodeName in driven, [float(v) for v in inputs[c.node.nodeName]])
        return data
    if frame.kind == frames.STOP:
        return {c: gp.text(gp.STOP, frame.reason) for c in conns}
    return {}


class Gateway:
    """The TCP gateway of one relay (see the module's text): accepts bridge FMUs for the project's
    nodes, each connection an ordinary node to the relay, until :meth:`close`."""

    def __init__(self, nodes: list[Node], session: zenoh.Session, keys: ProjectKeys, host: str, port: int,
                 drop: Callable[..., None], rates: dict[str, int] | None = None, stop_time: float = math.inf,
                 hello_timeout: float = 10.0):
        self._nodes = {n.nodeName: n for n in nodes}
        self._rates = rates or {}
        self._stop_time = stop_time
        self._session = session
        self._keys = keys
        self._drop = drop
        self._hello_timeout = hello_timeout
        self._conns: dict[str, _Connection] = {}
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._started = threading.Event()  # START sent: a bridge FMU attaching now is too late
        self._handshakes = threading.BoundedSemaphore(_MAX_HANDSHAKES)
        self._log = structlog.get_logger("server.gateway")
        try:
            self._listener = socket.create_server((host, port), family=listen_family(host), reuse_port=False)
        except OSError as exc:
            raise GatewayError(f"cannot listen for bridge FMUs on {Address(host, port)}: {exc.strerror or exc}") from None
        self.address = str(Address(host, self._listener.getsockname()[1]))
        # Declared when the first bridge FMU attaches: a callback subscriber on ``down`` runs
        # inside every release the relay puts, which cost a gateway-less run ~40 µs a step.
        self._down: zenoh.Subscriber | None = None
        self._accepter = threading.Thread(target=self._accept, name="gateway-accept", daemon=True)
        self._accepter.start()

    # --- attach ---------------------------------------------------------------------

    def _accept(self) -> None:
        while not self._closing.is_set():
            try:
                sock, peer = self._listener.accept()
            except OSError:
                return
            # A thread per connection, and one waits up to hello_timeout for a HELLO: bound how
            # many a flood of connections that never speak can hold at once.
            if not self._handshakes.acquire(blocking=False):
                self._drop("refused", f"connection from {peer}: {_MAX_HANDSHAKES} attaches already pending", -1)
                sock.close()
                continue
            threading.Thread(target=self._serve, args=(sock, peer), name=f"gateway-{peer}", daemon=True).start()

    def _refuse(self, sock: socket.socket, reason: str, counted_as: str) -> None:
        self._drop(counted_as, reason, -1)
        try:
            sock.sendall(gp.text(gp.REFUSE, reason))
        except OSError:
            pass
        sock.close()

    def _hello(self, sock: socket.socket) -> Node | None:
        sock.settimeout(self._hello_timeout)
        try:
            kind, payload = gp.read_frame(sock)
            if kind != gp.HELLO:
                raise gp.ProtocolError(f"expected HELLO, got frame type {kind}")
            uid, name, n_out, n_in = gp.parse_hello(payload)
        except (gp.ProtocolError, EOFError, OSError) as exc:
            self._refuse(sock, f"bad attach: {exc}", "malformed")
            return None
        node = self._nodes.get(name)
        if node is None or node.asynchronous:
            self._refuse(sock, f"no stepping node named {frames.short(name)} in this project", "unknown sender")
            return None
        if uid != node.UID:
            self._refuse(sock, f"UID {uid} does not own node {name!r}", "not owner")
            return None
        if (n_out, n_in) != (len(node.output), len(node.input)):
            self._refuse(sock, f"node {name!r} has {len(node.output)} outputs and {len(node.input)} inputs, "
                               f"the FMU declares {n_out} and {n_in}: rebuild it from this project", "unknown ports")
            return None
        if self._started.is_set():
            # Its START is gone, and a node restarted mid-run has lost the state the run needs.
            self._refuse(sock, f"node {name!r}: the run was already under way when it attached; a node joins "
                               "before the run starts: start the run again", "late attach")
            return None
        if token_held(self._session, self._keys.alive(name), timeout=self._hello_timeout):
            self._refuse(sock, f"node {name!r} is already attached: a process on Zenoh holds its liveliness token",
                         "not owner")
            return None
        with self._lock:
            if name in self._conns:
                self._refuse(sock, f"node {name!r} is already attached", "not owner")
                return None
            sock.settimeout(None)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            try:
                # First on the connection: a release can follow as soon as the token below is seen.
                sock.sendall(gp.frame(gp.WELCOME))
            except OSError:
                sock.close()
                return None
            if self._down is None:
                # Before the node is announced, so the release that follows reaches it.
                self._down = self._session.declare_subscriber(self._keys.down, self._on_down)
            # Last: the relay counts the node attached once it sees the token.
            token = self._session.liveliness().declare_token(self._keys.alive(name))
            self._conns[name] = _Connection(sock, node, token, self._rates.get(name, 1))
        return node

    def _serve(self, sock: socket.socket, peer: object) -> None:
        try:
            node = self._hello(sock)
        finally:
            self._handshakes.release()
        if node is None:
            return
        name = node.nodeName
        with self._lock:
            conn = self._conns[name]
        log = self._log.bind(node=name, peer=str(peer))
        log.info("bridge FMU attached")
        convert = [_FROM_WIRE[p.type] for p in node.output]
        key = self._keys.up(name)
        try:
            while True:
                kind, payload = gp.read_frame(sock)
                if kind != gp.OUTPUTS:
                    self._drop("wrong kind", f"{name} sent gateway frame type {kind}", -1, name)
                    continue
                try:
                    step, t, values = gp.parse_outputs(payload)
                except gp.ProtocolError as exc:
                    self._drop("malformed", f"from {name}: {exc}", -1, name)
                    continue
                if len(values) != len(convert):
                    self._drop("unknown ports", f"{name} sent {len(values)} values for {len(convert)} outputs", -1,
                               name)
                    continue
                label = conn.label(step)
                if label is None or not math.isfinite(t):
                    self._drop("wrong step", f"{name} sent the outputs of its step {step} at t={t}; "
                                             f"it was released {conn.released[0]} times", -1, name)
                    continue
                try:
                    typed = [c(v) for c, v in zip(convert, values)]
                except ValueError as exc:
                    self._drop("wrong type", f"{name}: {exc}", -1, name)
                    continue
                self._session.put(key, frames.encode(frames.OUTPUTS, node.UID, label, t, typed),
                                  allowed_destination=zenoh.Locality.SESSION_LOCAL,
                                  congestion_control=zenoh.CongestionControl.BLOCK)
        except gp.Truncated as exc:
            self._drop("truncated", f"{name}: {exc}", -1, name)
        except gp.ProtocolError as exc:
            self._drop("malformed", f"{name}: {exc}", -1, name)
        except (EOFError, OSError):
            pass
        finally:
            with self._lock:
                conn = self._conns.pop(name, None)
            sock.close()
            if conn is not None:
                try:
                    conn.token.undeclare()
                except zenoh.ZError:  # the session closed first: the token went with it
                    pass
            if not self._closing.is_set():
                log.info("bridge FMU detached")

    def run_started(self) -> None:
        """The relay sent START: from now on a bridge FMU that attaches is refused."""
        self._started.set()

    # --- releases -------------------------------------------------------------------

    def _on_down(self, sample: zenoh.Sample) -> None:
        with self._lock:
            conns = list(self._conns.values())
        if not conns:
            return
        try:
            data = translate_release(sample.payload.to_bytes(), conns, self._stop_time)
        except frames.FrameError as exc:
            # The down key is open to anyone on an unsecured network; only the server's releases pass.
            self._drop("malformed release", f"on the release key: {exc}", -1)
            return
        for conn, payload in data.items():
            if gp.HEADER.unpack_from(payload)[2] == gp.STEP:
                conn.releasing(gp.parse_step(payload[gp.HEADER.size:])[0])
            try:
                conn.send(payload)
            except OSError:
                pass  # the reader thread reports the loss

    def close(self, reason: str = "the server stopped") -> None:
        """Stop accepting, tell every connected bridge FMU the run is over (``reason``, as a STOP) and
        close its connection; undeclare what the gateway declared. Safe to call more than once."""
        self._closing.set()
        with self._lock:
            down, self._down = self._down, None
        try:
            if down is not None:
                down.undeclare()
        except Exception:
            pass
        self._listener.close()
        with self._lock:
            conns = list(self._conns.values())
        for c in conns:
            try:
                # STOP may already be on its way from _on_down; a second one is never read.
                c.send(gp.text(gp.STOP, reason))
                c.sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
