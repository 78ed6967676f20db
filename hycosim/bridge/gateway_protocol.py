"""The TCP gateway framing between generated bridge FMUs (C) and the relay server.

A tool that can only import FMUs joins a co-simulation with nothing but the file: the
bridge FMU speaks this small protocol over one TCP connection; the server's gateway
puts it on the same barrier as Zenoh nodes. Version 1, all integers little-endian.

Every frame is a 12-byte header and a payload::

    magic "HYCO" | version u8 (=1) | type u8 | reserved u16 (=0) | length u32 | payload

=========  ==========  ==============================================================
type       direction   payload
=========  ==========  ==============================================================
1 HELLO    FMU→server  uid u32, name_len u16, name (UTF-8), n_outputs u16, n_inputs u16
2 WELCOME  server→FMU  (empty): attached
3 REFUSE   server→FMU  reason (UTF-8); the server closes the connection
4 START    server→FMU  t0 f64, H f64
5 OUTPUTS  FMU→server  step i64, t f64, n u16, n × f64 (the node's outputs, port order)
6 STEP     server→FMU  step i64, t f64, h f64, driven u8, n u16, n × f64 (the node's inputs)
7 STOP     server→FMU  reason (UTF-8)
=========  ==========  ==============================================================

"outputs" and "inputs" are the node's, as in the project JSON. START's H is the node's own
step (its ``stepSize``, a multiple of the run's in a multi-rate run). OUTPUTS's step is the
FMU's count of its own steps: 0 at the start, n after its n-th STEP; the gateway takes it
only as the answer to the n-th STEP it sent (a node is sent only the STEPs of its own steps).
STEP's step and t are the server's, at the start of the node's step. Integer and Boolean
ports travel as f64 (exact up to 2^53). A payload is at most 1 MiB. The C side of this
file is ``hycosim/bridge/templates/bridge_fmu.c``; keep the two in step.
"""

from __future__ import annotations

import socket
import struct

MAGIC = b"HYCO"
VERSION = 1
HEADER = struct.Struct("<4sBBHI")
MAX_PAYLOAD = 1 << 20

HELLO, WELCOME, REFUSE, START, OUTPUTS, STEP, STOP = range(1, 8)


class ProtocolError(ValueError):
    """A frame that breaks the framing: bad magic, version, type, length or payload."""


class Truncated(ProtocolError):
    """The connection ended inside a frame."""


def frame(kind: int, payload: bytes = b"") -> bytes:
    """One complete frame."""
    return HEADER.pack(MAGIC, VERSION, kind, 0, len(payload)) + payload


def hello(uid: int, name: str, n_outputs: int, n_inputs: int) -> bytes:
    """A HELLO frame: the bridge FMU's UID, its node's name and its numbers of outputs and inputs."""
    raw = name.encode()
    return frame(HELLO, struct.pack("<IH", uid, len(raw)) + raw + struct.pack("<HH", n_outputs, n_inputs))


def parse_hello(payload: bytes) -> tuple[int, str, int, int]:
    """uid, node name, number of outputs and inputs of a HELLO payload; ProtocolError if malformed."""
    if len(payload) < 6:
        raise ProtocolError(f"bad HELLO payload: {len(payload)} bytes, shorter than its 6-byte start")
    uid, n = struct.unpack_from("<IH", payload)
    if len(payload) != 6 + n + 4:
        raise ProtocolError(f"bad HELLO payload: a {n}-byte name and two counts need {6 + n + 4} bytes, "
                            f"it has {len(payload)}")
    try:
        name = payload[6:6 + n].decode()
    except UnicodeDecodeError:
        raise ProtocolError("bad HELLO payload: the node name is not UTF-8") from None
    n_out, n_in = struct.unpack_from("<HH", payload, 6 + n)
    return uid, name, n_out, n_in


def start(t0: float, h: float) -> bytes:
    """A START frame: the run's start time and the node's own step size."""
    return frame(START, struct.pack("<dd", t0, h))


def outputs(step: int, t: float, values: list[float]) -> bytes:
    """An OUTPUTS frame: the FMU's count of its own steps, its time and its output values (as f64)."""
    return frame(OUTPUTS, struct.pack(f"<qdH{len(values)}d", step, t, len(values), *values))


def parse_outputs(payload: bytes) -> tuple[int, float, list[float]]:
    """Step count, time and values of an OUTPUTS payload; ProtocolError where its length does not match
    the values it declares."""
    try:
        step, t, n = struct.unpack_from("<qdH", payload)
        if len(payload) != 18 + 8 * n:
            raise ProtocolError(f"OUTPUTS declares {n} values in {len(payload)} bytes")
        return step, t, list(struct.unpack_from(f"<{n}d", payload, 18))
    except struct.error as exc:
        raise ProtocolError(f"bad OUTPUTS payload: {exc}") from None


def step(k: int, t: float, h: float, driven: bool, values: list[float]) -> bytes:
    """A STEP frame: the server's step and time at the node's step start, its length, whether the node
    is driven, and its input values (as f64)."""
    return frame(STEP, struct.pack(f"<qddBH{len(values)}d", k, t, h, int(driven), len(values), *values))


def parse_step(payload: bytes) -> tuple[int, float, float, bool, list[float]]:
    """Step, time, step size, driven flag and input values of a STEP payload: one the gateway
    itself wrote (the C side reads its own copy), so its length is not checked."""
    k, t, h, driven, n = struct.unpack_from("<qddBH", payload)
    return k, t, h, bool(driven), list(struct.unpack_from(f"<{n}d", payload, 27))


def text(kind: int, message: str) -> bytes:
    """A frame of ``kind`` carrying ``message`` as UTF-8, cut to the largest payload (REFUSE, STOP)."""
    return frame(kind, message.encode()[:MAX_PAYLOAD])


def _read_exact(sock: socket.socket, n: int, started: bool) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            if buf or started:
                raise Truncated(f"connection closed {len(buf)} bytes into a {n}-byte read")
            raise EOFError("connection closed")
        buf += chunk
    return bytes(buf)


def read_frame(sock: socket.socket) -> tuple[int, bytes]:
    """Read one frame; EOFError at a clean end, Truncated inside a frame, ProtocolError otherwise."""
    magic, version, kind, _, length = HEADER.unpack(_read_exact(sock, HEADER.size, started=False))
    if magic != MAGIC:
        raise ProtocolError(f"bad magic {magic!r}")
    if version != VERSION:
        raise ProtocolError(f"protocol version {version}, this server speaks {VERSION}")
    if not HELLO <= kind <= STOP:
        raise ProtocolError(f"unknown frame type {kind}")
    if length > MAX_PAYLOAD:
        raise ProtocolError(f"payload of {length} bytes exceeds {MAX_PAYLOAD}")
    return kind, _read_exact(sock, length, started=True)
