"""Hypothesis strategies for what can arrive on hycosim's wire: structure-aware frames and raw bytes.

A frame strategy draws ``[version, kind, fields...]`` with the right version and arity most
of the time and each field either of the type its position expects (plausible values: small
UIDs, node names of the project, steps near the run's) or any msgpack value, so that the
receivers' checks are reached field by field, not only the first.
"""

from __future__ import annotations

import socket
import struct

import msgpack
from hypothesis import strategies as st

from hycosim.core import frames
from hycosim.bridge import gateway_protocol as gp

NAMES = ["a", "g", "clock", "src", "s", "_server", "_local", "nobody", ""]

scalars = (st.none() | st.booleans() | st.integers(-(2 ** 63), 2 ** 64 - 1) | st.integers(-3, 3)
           | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=12) | st.binary(max_size=12))
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4)
                      | st.dictionaries(st.text(max_size=6) | st.integers(-3, 3), inner, max_size=4), max_leaves=10)
names = st.sampled_from(NAMES) | st.text(max_size=10)
# JSON text nested deeper than Python's decoder recurses (about 1,000 levels; 2,048 under
# hypothesis), or not quite, closed or not. The depths are a few fixed values: drawn from a
# range, 40 examples did not reach a failing one.
deep_json = st.sampled_from([1, 900, 3000]).flatmap(
    lambda d: st.sampled_from(["[" * d + "]" * d, '{"a": ' * d + "1" + "}" * d, "[" * d]))
uids = st.integers(-1, 5)
steps = st.integers(-2, 6) | st.integers(-(2 ** 63), 2 ** 64 - 1)
times = st.floats(allow_nan=True, allow_infinity=True) | st.integers(-2, 2)
port_values = st.lists(scalars, max_size=4)
# A STEP's input derivatives per node: per input None or a few numbers (sometimes too many, or not finite).
slopes = st.dictionaries(names, st.lists(st.none() | st.lists(times, max_size=frames.MAX_SLOPE_ORDER + 1) | scalars,
                                         max_size=4), max_size=3)


def _or_any(strategy: st.SearchStrategy) -> st.SearchStrategy:
    return st.one_of(strategy, strategy, strategy, values)


_PLAUSIBLE: dict[int, tuple[st.SearchStrategy, ...]] = {
    frames.OUTPUTS: (uids, steps, times, port_values),
    frames.SAMPLE: (uids, steps, times, port_values),
    frames.START: (names, times, times, times, st.none() | times,
                   st.fixed_dictionaries({"checkpoint": st.booleans()}) | values),
    frames.STEP: (steps, times, times, names, st.dictionaries(names, port_values, max_size=3),
                  st.lists(names, max_size=3), st.just({}) | slopes),
    frames.STOP: (steps, st.sampled_from(list(frames.CLEAN_STOPS)) | st.text(max_size=20)),
    frames.LIVE: (names, st.booleans()),
    frames.HELLO: (uids, st.fixed_dictionaries({"rollback": values, "restart": st.booleans() | values,
                                                "ports": values}) | values),
    frames.ROLLBACK: (steps, times),
    frames.END: (uids, steps, times, st.booleans(), st.text(max_size=30),
                 st.just([]) | st.lists(port_values | scalars, max_size=3), st.none() | port_values),
    frames.CHECKPOINT: (steps,),
    frames.STATE: (uids, steps, st.integers(-1, 3), st.integers(-1, 3) | st.integers(0, 2 ** 20), st.binary(max_size=24)),
    frames.RESTORE: (names, steps, times, st.integers(-1, 3), st.integers(-1, 3), st.binary(max_size=24),
                     st.fixed_dictionaries({"checkpoint": st.booleans()}) | values),
    # Batched releases: times mostly rising and few, sometimes too many, unsorted or not finite.
    frames.STEPS: (steps, st.lists(st.floats(0.0, 10.0), min_size=2, max_size=4).map(sorted)
                   | st.lists(times, max_size=4) | st.just([0.0] * (frames.MAX_BATCH + 2)),
                   names, st.dictionaries(names, port_values, max_size=3), st.lists(names, max_size=3)),
    frames.BATCH: (uids, steps, times, port_values, st.lists(port_values | scalars, max_size=3)
                   | st.just([[0.0]] * frames.MAX_BATCH)),
    frames.INIT: (times, st.dictionaries(names, port_values, max_size=3), st.booleans()),
    frames.TUNE: (names, steps, times, st.dictionaries(st.sampled_from(["k", "b", "i", "nope"]) | st.text(max_size=4),
                                                       scalars, max_size=3)),
}


def frame_arrays(kinds: list[int] | None = None) -> st.SearchStrategy:
    """``[version, kind, fields...]`` arrays, mostly of the right shape, one field at a time wrong."""
    chosen = kinds or [*_PLAUSIBLE, frames.REPLAY]

    @st.composite
    def draw(draw_) -> list:
        kind = draw_(st.sampled_from(chosen))
        if kind == frames.REPLAY:
            inner = draw_(frame_arrays([frames.START, frames.STEP, frames.STEPS, frames.STOP, frames.OUTPUTS,
                                             frames.INIT]))
            fields = [draw_(_or_any(names)), draw_(st.just(msgpack.packb(inner)) | st.binary(max_size=16))]
        else:
            fields = [draw_(_or_any(s)) for s in _PLAUSIBLE[kind]]
        arity = draw_(st.sampled_from([len(fields)] * 6 + [len(fields) - 1, len(fields) + 1]))
        fields = (fields + [None])[:arity]
        version = draw_(st.sampled_from([frames.VERSION] * 8) | scalars)
        kind_field = draw_(st.sampled_from([kind] * 8) | values)
        return [version, kind_field, *fields]

    return draw()


def _deep(depth: int) -> bytes:
    return b"\x91" * depth + b"\xc0"


payloads = st.one_of(
    frame_arrays().map(lambda arr: msgpack.packb(arr, use_bin_type=True)),
    frame_arrays().map(lambda arr: msgpack.packb(arr, use_bin_type=True)),
    frame_arrays().map(lambda arr: msgpack.packb(arr, use_bin_type=True)),
    st.binary(max_size=64),
    values.map(lambda v: msgpack.packb(v, use_bin_type=True)),
    st.integers(1, 5000).map(_deep),
    st.binary(min_size=1, max_size=40).map(lambda b: b[:1] + b"\xff" * 8),  # lengths that run past the end
)


@st.composite
def gateway_streams(draw_) -> bytes:
    """What a peer may write on the gateway socket: frames with any header field wrong, payloads
    of any size for their kind, and raw bytes."""
    parts = []
    for _ in range(draw_(st.integers(1, 4))):
        kind = draw_(st.integers(0, 9))
        payload = draw_(st.one_of(
            st.binary(max_size=48),
            st.builds(lambda uid, name, o, i: struct.pack("<IH", uid, len(name)) + name + struct.pack("<HH", o, i),
                      st.integers(0, 2 ** 32 - 1), st.binary(max_size=8), st.integers(0, 4), st.integers(0, 4)),
            st.builds(lambda k, t, vs: struct.pack(f"<qdH{len(vs)}d", k, t, len(vs), *vs),
                      st.integers(-(2 ** 63), 2 ** 63 - 1), st.floats(), st.lists(st.floats(), max_size=4))))
        magic = draw_(st.sampled_from([gp.MAGIC, gp.MAGIC, b"HYCX"]))
        version = draw_(st.sampled_from([gp.VERSION, gp.VERSION, 0, 255]))
        length = draw_(st.sampled_from([len(payload)] * 4 + [len(payload) + 3, 2 ** 32 - 1]))
        parts.append(gp.HEADER.pack(magic, version, kind, 0, length) + payload)
    return b"".join(parts) + draw_(st.binary(max_size=8))


def examples(strategy: st.SearchStrategy, n: int) -> list:
    """``n`` examples of a strategy, the same on every call (derandomized): a corpus to send."""
    from hypothesis import HealthCheck, given, settings

    found: list = []

    @settings(max_examples=n, derandomize=True, database=None, deadline=None,
              suppress_health_check=list(HealthCheck))
    @given(strategy)
    def collect(example) -> None:
        found.append(example)

    collect()
    return found


def forgeable(payload: bytes, key: str, uids: dict[str, int]) -> bool:
    """Whether a payload written on ``key`` is a frame the project's own sender could have sent:
    on ``up/<node>`` an OUTPUTS, SAMPLE, END or BATCH with that node's UID and a step in the run's
    range; on ``down`` a STEP, STEPS, STOP or a REPLAY naming a node. On a network without access control such
    a frame cannot be told from the real one (that is what credentials and ACL are for), so the
    live fuzz of an open project leaves them out. Deliberately simpler than the receivers' checks."""
    try:
        obj = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception:
        return False
    if type(obj) is not list or len(obj) < 2 or type(obj[0]) is not int or obj[0] != frames.VERSION \
            or type(obj[1]) is not int:
        return False
    chunks = key.split("/")
    if chunks[-2:-1] == ["up"]:
        owner = uids.get(chunks[-1])
        return (obj[1] in (frames.OUTPUTS, frames.SAMPLE, frames.END, frames.BATCH) and len(obj) > 3
                and owner is not None
                and obj[2] == owner and type(obj[3]) is int and 0 <= obj[3] < 10 ** 7)
    if chunks[-1] == "down":
        if obj[1] == frames.REPLAY:
            return len(obj) > 2 and type(obj[2]) is str and obj[2] in uids
        return obj[1] in (frames.STEP, frames.STEPS, frames.STOP)
    return False


def send_to_gateway(port: int, streams: list[bytes]) -> int:
    """Write each stream on a connection of its own to the gateway on 127.0.0.1; the number written."""
    sent = 0
    for stream in streams:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=2.0) as s:
                s.sendall(stream)
                sent += 1
                s.settimeout(0.02)
                try:
                    s.recv(4096)  # a REFUSE, if the gateway answers
                except OSError:
                    pass
        except OSError:
            pass
    return sent
