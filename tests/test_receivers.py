"""Every receiver is total: property-based tests feed each one what the network may bring.

In process, with hypothesis: frame decoding, the server's intake and side-message handling,
its gathering of a batched release's answers and of a source's END, a node's release
handling, the gateway's framing and its translation of releases, and the bounded drop log.
Whatever the bytes, each returns something it can act on or drops it with its own exception;
nothing else escapes.
"""

from __future__ import annotations

import json
import math
import socket
import threading
from pathlib import Path

import msgspec
import pytest
import structlog
from hypothesis import event, given
from hypothesis import strategies as st

from hycosim.core import frames
from hycosim.bridge import gateway_protocol as gp
from hycosim.core.schema import WIRE_TYPES, PortType
from hycosim.core.config import load_project
from hycosim.core.drops import DropLog
from hycosim.bridge.gateway import _Connection, translate_release
from hycosim.master.intake import Dropped, Intake
from hycosim.master.recorder import Recorder
from hycosim.master.relay import Relay
from hycosim.transport.server_side import ZenohTransport
from hycosim.node.runtime import NodeRuntime
from tests.helpers import write_project
from tests.wire_strategies import frame_arrays, gateway_streams, names, payloads, values

NODES = [
    {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
    {"nodeName": "g", "UID": 2, "model": "gain", "input": ["u"],
     "output": ["y", {"name": "n", "type": "Integer"}, {"name": "b", "type": "Boolean"},
                {"name": "s", "type": "String"}, {"name": "raw", "type": "Binary"}]},
    {"nodeName": "h", "UID": 3, "model": "gain", "input": ["u", {"name": "k", "type": "Integer"},
                                                           {"name": "on", "type": "Boolean"}], "output": ["y"]},
    {"nodeName": "src", "UID": 4, "model": "ramp_source", "async": True, "rate": 10, "output": ["y"]},
]


@pytest.fixture(scope="module")
def loaded(tmp_path_factory):
    path = write_project(tmp_path_factory.mktemp("recv") / "p.json", NODES,
                         [{"from": "clock.y", "to": "g.u"}, {"from": "g.y", "to": "h.u"}], name="recv")
    return load_project(path)


# The same nodes with two events that drive ``h``: releases in three modes, two of them naming the
# same driven node (only the mode tells them apart).
GRASPED = {"name": "grasped", "when": "clock.y > 1", "drives": "h", "until": "clock.y > 2"}
HELD = {"name": "held", "when": "clock.y > 3", "drives": "h", "until": "clock.y > 4"}


@pytest.fixture(scope="module")
def loaded_events(tmp_path_factory):
    path = write_project(tmp_path_factory.mktemp("recv") / "p.json", NODES,
                         [{"from": "clock.y", "to": "g.u"}, {"from": "g.y", "to": "h.u", "activeIn": ["free"]},
                          {"from": "clock.y", "to": "h.u", "activeIn": ["grasped", "held"]}],
                         events=[GRASPED, HELD], name="recv")
    return load_project(path)


def _quiet() -> None:
    structlog.configure(logger_factory=structlog.ReturnLoggerFactory())


_VALUE = {"Real": st.floats(allow_nan=True, allow_infinity=True) | st.integers(-3, 3), "Integer": st.integers(-3, 3),
          "Boolean": st.booleans(), "String": st.text(max_size=4), "Binary": st.binary(max_size=4)}
_SENDERS = {n["nodeName"]: (n["UID"], [p["type"] if isinstance(p, dict) else "Real" for p in n["output"]])
            for n in NODES}
_OUTPUTS = {node: st.tuples(*[_VALUE[type_] for type_ in types]).map(list) for node, (_, types) in _SENDERS.items()}
_ODD = ["1", True, None, b"\x00", [], {}, 1.5, 7]  # each of the wrong type for some port
_KINDS = {frames.OUTPUTS, frames.SAMPLE, frames.END, frames.BATCH, frames.STATE}
_WRONGS = [None, "kind", "uid", "step", "t", "value", "ports", "batch", "field"]  # "field": any value in any field


@st.composite
def _from_a_node(draw, wrong: str | None = "any") -> tuple[str, bytes, int, str | None]:
    """A frame on a node's own key as that node would write it (its UID, a kind it sends, one
    value of its type for each of its outputs, a step and time in range), with at most one
    thing wrong: the generic strategies, which draw UIDs and values blind, reach an accepted
    OUTPUTS, SAMPLE, END or BATCH about once in tens of thousands of frames. Also returns the
    kind and what is wrong (``wrong``: that, or any of _WRONGS)."""
    node = draw(st.sampled_from(sorted(_SENDERS)))
    uid, types = _SENDERS[node]
    source = node == "src"
    sends = [frames.SAMPLE, frames.END] if source else [frames.OUTPUTS, frames.END, frames.BATCH, frames.STATE]
    outputs = _OUTPUTS[node]
    if wrong == "any":
        wrong = draw(st.sampled_from([None, *_WRONGS]))
    kind = draw(st.sampled_from(sorted(_KINDS - set(sends)) if wrong == "kind" else sends))
    step, t = draw(st.integers(0, 40)), draw(st.floats(0, 10))
    if wrong == "uid":
        uid = draw(st.integers(-1, 5).filter(lambda u: u != uid))
    elif wrong == "step":
        step = draw(st.sampled_from([-1, -(2 ** 63), frames.MAX_STEP, 2 ** 64 - 1]))
    elif wrong == "t":
        t = draw(st.sampled_from([math.nan, math.inf, -math.inf]))
    elif wrong == "value":  # one port's value of another type
        at = draw(st.integers(0, len(types) - 1))
        odd = st.sampled_from([v for v in _ODD if type(v) not in WIRE_TYPES[PortType(types[at])]])
        outputs = outputs.flatmap(lambda vs: odd.map(lambda v: vs[:at] + [v] + vs[at + 1:]))
    elif wrong == "ports":  # a value too few or too many
        outputs = outputs.flatmap(lambda vs: st.sampled_from([vs[:-1], vs + [0.5]]))
    # A source's END only says it failed or was stopped: unclean, no batch.
    # Anyone else's: clean or not, a batch's earlier outputs or none, its outputs where it ended or none.
    end = ([st.just(False), st.text(max_size=20), st.just([]), st.none()] if source else
           [st.booleans(), st.text(max_size=20), st.just([]) | st.lists(outputs, min_size=1, max_size=3),
            st.none() | outputs])
    tail = {frames.OUTPUTS: [outputs], frames.SAMPLE: [outputs], frames.END: end,
            frames.BATCH: [outputs, st.lists(outputs, max_size=3)],
            frames.STATE: [st.integers(0, 2), st.just(3), st.binary(max_size=16)]}[kind]
    fields = [uid, step] + ([] if kind == frames.STATE else [t]) + [draw(part) for part in tail]
    if wrong == "batch" and kind in (frames.END, frames.BATCH):  # one step more than a batch may hold
        fields[-2 if kind == frames.END else -1] = [draw(outputs)] * frames.MAX_BATCH
    if wrong == "field":
        fields[draw(st.integers(0, len(fields) - 1))] = draw(values)
    return node, frames.encode(kind, *fields), kind, wrong


_RECEIVERS = {n["nodeName"]: [p["type"] if isinstance(p, dict) else "Real" for p in n.get("input", [])]
              for n in NODES if not n.get("async")}
_INPUTS = {node: st.tuples(*[_VALUE[type_] for type_ in types]).map(list) for node, types in _RECEIVERS.items()}
_NOT_FOR_A_NODE = [frames.OUTPUTS, frames.SAMPLE, frames.HELLO, frames.END, frames.STATE, frames.BATCH, frames.LIVE]
_RELEASE_WRONGS = [None, "others", "kind", "step", "t", "value", "ports", "slopes", "chunk", "replay", "field"]


@st.composite
def _from_the_server(draw, node: str, wrong: str | None = "any") -> tuple[bytes, int, str | None]:
    """A frame on ``down`` as this project's server writes it for ``node`` (a release with every
    stepping node's inputs of their types, times finite and rising, a replay or a state piece
    for it, a rollback, checkpoint or stop), with at most one thing wrong: the generic
    strategies reached no release a node acts on in 3,000 frames. ``others``: one meant for
    other nodes (a release without it, a replay or state piece for another). Also returns the
    kind and what is wrong (``wrong``: that, or any of _RELEASE_WRONGS)."""
    if wrong == "any":  # a right frame one time in three: the properties hold of what is acted on
        wrong = draw(st.sampled_from([None] * 5 + _RELEASE_WRONGS))
    only = {"value": [frames.STEP, frames.STEPS, frames.REPLAY, frames.INIT],
            "ports": [frames.STEP, frames.STEPS, frames.REPLAY, frames.INIT],
            "others": [frames.STEP, frames.STEPS, frames.REPLAY, frames.RESTORE, frames.INIT],
            "step": [frames.STEP, frames.STEPS, frames.ROLLBACK, frames.CHECKPOINT, frames.RESTORE, frames.REPLAY],
            "t": [frames.START, frames.STEP, frames.STEPS, frames.ROLLBACK, frames.RESTORE, frames.REPLAY, frames.INIT],
            "slopes": [frames.STEP], "chunk": [frames.RESTORE], "replay": [frames.REPLAY],
            "kind": _NOT_FOR_A_NODE}.get(wrong)
    kind = draw(st.sampled_from(only or [frames.START, frames.STEP, frames.STEPS, frames.STOP, frames.ROLLBACK,
                                         frames.CHECKPOINT, frames.REPLAY, frames.RESTORE, frames.INIT]))
    if kind in _NOT_FOR_A_NODE:  # its own version and kind, so that it is decoded as one
        return draw(frame_arrays([kind]).map(lambda a: frames.msgpack.packb([frames.VERSION, kind, *a[2:]]))), \
            kind, wrong
    k, t = draw(st.integers(0, 40)), draw(st.floats(0, 10))
    if wrong == "step":
        k = draw(st.sampled_from([-1, -(2 ** 63), frames.MAX_STEP, 2 ** 64 - 1]))
    bad_t = st.sampled_from([math.nan, math.inf, -math.inf])
    if kind == frames.RESTORE:
        count = draw(st.integers(1, 4))
        fields = [node, k, t, draw(st.integers(0, count - 1)), count, draw(st.binary(max_size=16)),
                  {"checkpoint": draw(st.booleans())}]
        if wrong == "t":
            fields[2] = draw(bad_t)
        elif wrong == "others":
            fields[0] = draw(st.sampled_from(sorted(set(_RECEIVERS) - {node})))
        elif wrong == "chunk":  # a piece beyond its count, no pieces, too many, or a piece too long
            at = draw(st.integers(0, 2))
            fields[3:6] = [[count, count, fields[5]], [0, draw(st.sampled_from([0, -1])), fields[5]],
                           [0, frames.MAX_CHUNKS + 1, fields[5]], [0, 1, b"\0" * (frames.STATE_CHUNK + 1)]][at]
    elif kind in (frames.ROLLBACK, frames.CHECKPOINT, frames.STOP):
        fields = {frames.ROLLBACK: [k, draw(bad_t) if wrong == "t" else t], frames.CHECKPOINT: [k],
                  frames.STOP: [k, draw(st.sampled_from(list(frames.CLEAN_STOPS)) | st.text(max_size=20))]}[kind]
    else:
        inner = kind
        if kind == frames.REPLAY:  # of a release with inputs, where what is wrong is in them or its step
            inner = draw(st.sampled_from([frames.STEP, frames.STEPS] if wrong in ("value", "ports", "step")
                                         else [frames.START, frames.STEP, frames.STEPS]))
        released = draw(st.sets(st.sampled_from(sorted(_RECEIVERS)))) | {node}
        inputs = {n: draw(_INPUTS[n]) for n in sorted(released)}
        if wrong == "others" and kind != frames.REPLAY:
            del inputs[node]
        elif wrong == "value":  # one input's value of another type, or none at all
            at = draw(st.integers(0, len(_RECEIVERS[node]) - 1))
            types = WIRE_TYPES[PortType(_RECEIVERS[node][at])]
            inputs[node][at] = draw(st.sampled_from([v for v in _ODD if type(v) not in types]))
            if draw(st.booleans()):
                inputs[node] = draw(st.sampled_from([None, 0.5, "u", {}]))
        elif wrong == "ports":
            inputs[node] = draw(st.sampled_from([inputs[node][:-1], inputs[node] + [0.5]]))
        driven = sorted(draw(st.sets(st.sampled_from(sorted(_RECEIVERS)))))
        mode = draw(st.sampled_from(["free", "grasped"]))
        h = draw(st.floats(1e-4, 1.0))
        if inner == frames.START:
            fields = [draw(st.text(max_size=8)), t, h, draw(st.floats(0, 2e9)), draw(st.none() | st.floats(0.1, 10)),
                      {"checkpoint": draw(st.booleans())}]
            if wrong == "t":  # a time not finite, or a step size or real-time factor not above 0
                at = draw(st.integers(1, 4))
                fields[at] = draw(bad_t | st.sampled_from([0.0, -0.1]) if at in (2, 4) else bad_t)
        elif inner == frames.INIT:  # the initialisation's inputs at t0
            fields = [draw(bad_t) if wrong == "t" else t, inputs, draw(st.booleans())]
        elif inner == frames.STEP:
            others = {n: [draw(st.floats(-1, 1))] for n in draw(st.sets(st.sampled_from(["clock", "src"])))}
            fields = [k, t, h, mode, inputs, driven, others]  # slopes only for nodes that interpolate
            if wrong == "t":  # a time not finite, or a step size not above 0
                at = draw(st.integers(1, 2))
                fields[at] = draw(bad_t | st.sampled_from([0.0, -0.1]) if at == 2 else bad_t)
            elif wrong == "slopes":  # this node holds its inputs over a step
                fields[6] = {**others, node: [None] * len(_RECEIVERS[node])}
        else:
            times = sorted(draw(st.sets(st.floats(0, 10), min_size=2, max_size=5)))
            if wrong == "t":  # not rising, too many, or one not finite
                times = draw(st.sampled_from([times[::-1], [times[0]] * 2, [0.01 * i for i in range(frames.MAX_BATCH + 2)],
                                              times[:-1] + [math.nan]]))
            fields = [k, times, mode, inputs, driven]
        if kind == frames.REPLAY:
            release = frames.encode(inner, *fields)
            fields = [node, release]
            if wrong == "others":
                fields[0] = draw(st.sampled_from(sorted(set(_RECEIVERS) - {node})))
            elif wrong == "replay":  # of a frame that is not a release, or of no frame
                fields[1] = draw(st.sampled_from([frames.encode(frames.STOP, k, "done"),
                                                  frames.encode(frames.ROLLBACK, k, t),
                                                  frames.encode(frames.OUTPUTS, 2, k, t, [0.5]), b"\x00", b""]))
    if wrong == "field":
        fields[draw(st.integers(0, len(fields) - 1))] = draw(values)
    return frames.encode(kind, *fields), kind, wrong


@given(payloads)
def test_decode_returns_a_well_typed_frame_or_raises_frame_error(payload):
    try:
        frame = frames.decode(payload)
    except frames.FrameError as exc:
        assert len(str(exc)) < 400  # a hostile payload's size never reaches a message
        return
    arity, fits = frames._SHAPES[frame.kind]
    assert type(frame) is frames.TYPES[frame.kind] and len(frame) == arity and fits(frame)


@given(st.one_of(st.tuples(st.sampled_from(["clock", "g", "h", "src", "nobody", "_local"]) | names, payloads),
                 _from_a_node(), _from_a_node()))
def test_the_servers_intake_accepts_only_frames_it_can_use(loaded, sent):
    node, payload = sent[:2]
    _quiet()
    intake = Intake(loaded.project.nodeLists)
    try:
        frame = intake.accept(node, payload)
    except Dropped as exc:
        assert exc.reason and intake.dropped == {}  # counted by the caller
        return
    spec = loaded.project.node(node)
    assert frame.uid == spec.UID
    if frame.kind in (frames.OUTPUTS, frames.SAMPLE):
        number = frame.seq if frame.kind == frames.SAMPLE else frame.step
        assert 0 <= number < frames.MAX_STEP and math.isfinite(frame.t)
        assert [type(v) in WIRE_TYPES[p.type] for v, p in zip(frame.values, spec.output)] == [True] * len(spec.output)
    elif frame.kind == frames.BATCH:
        assert not spec.asynchronous and 0 <= frame.step < frames.MAX_STEP and math.isfinite(frame.t)
        assert len(frame.earlier) < frames.MAX_BATCH
        for step_values in [*frame.earlier, frame.values]:  # each step's outputs, all of its ports, each typed
            assert type(step_values) is list and len(step_values) == len(spec.output)
            assert all(type(v) in WIRE_TYPES[p.type] for v, p in zip(step_values, spec.output))
    elif frame.kind == frames.STATE:
        assert not spec.asynchronous and 0 <= frame.step < frames.MAX_STEP
        assert 0 <= frame.index < frame.count <= frames.MAX_CHUNKS and len(frame.chunk) <= frames.STATE_CHUNK
    elif frame.kind == frames.END:  # the outputs of its steps inside a batch before it ended, as a BATCH's
        # A source only says that it stopped or failed: it neither ends a run nor steps in a batch.
        assert not spec.asynchronous or (frame.clean is False and frame.earlier == [] and frame.last is None)
        assert len(frame.earlier) < frames.MAX_BATCH
        for step_values in [*frame.earlier, *([] if frame.last is None else [frame.last])]:
            assert type(step_values) is list and len(step_values) == len(spec.output)
            assert all(type(v) in WIRE_TYPES[p.type] for v, p in zip(step_values, spec.output))
    else:
        assert frame.kind == frames.HELLO


@pytest.mark.parametrize("wrong", _WRONGS)
@given(data=st.data())
def test_the_intake_takes_a_nodes_own_frame_only_when_nothing_in_it_is_wrong(loaded, wrong, data):
    """Each thing a frame can have wrong on its own (a kind its sender does not send, the UID, a
    step or time out of range, a value of another type, a value too few or too many, a batch
    too long) is caught; a right frame is taken."""
    node, payload, kind, _ = data.draw(_from_a_node(wrong))
    _quiet()
    carries = {"kind": True, "uid": True, "step": True, "t": kind != frames.STATE,
               "value": kind in (frames.OUTPUTS, frames.SAMPLE, frames.BATCH),
               "ports": kind in (frames.OUTPUTS, frames.SAMPLE, frames.BATCH),
               "batch": kind in (frames.END, frames.BATCH)}
    try:
        Intake(loaded.project.nodeLists).accept(node, payload)
    except Dropped:
        taken = False
    else:
        taken = True
    if carries.get(wrong):
        assert not taken, f"{node} {frames.KIND_NAMES[kind]} with its {wrong} wrong was taken"
    elif wrong is None:
        assert taken, f"{node}'s right {frames.KIND_NAMES[kind]} was dropped"


@pytest.fixture(scope="module")
def relay(loaded, tmp_path_factory):
    # One relay's barrier for every example: a stream of hostile frames through one server, as on the wire.
    _quiet()
    recorder = Recorder(tmp_path_factory.mktemp("relay"), loaded, {})
    # A transport never opened: nothing here touches the session, no release is sent.
    r = Relay(loaded, ZenohTransport(None), recorder)
    for node in ("clock", "g", "h", "src"):
        r.members.alive.add(node)
        r.members.capabilities[node] = {"rollback": False}
    yield r.barrier
    recorder.close("done")


@given(st.one_of(st.tuples(st.sampled_from(["clock", "g", "h", "src", "nobody", "_local", "*"]), payloads),
                 _from_a_node(), _from_a_node()))
def test_the_relay_drops_what_it_cannot_use_and_never_stops_on_a_payload(relay, sent):
    node, payload = sent[:2]
    before = sum(relay.intake.dropped.values())
    got = relay.take_in(f"hycosim/recv/up/{node}", payload, step=5, collecting=True)
    if got is None:
        return  # dropped (counted) or a sample taken into its history
    name, frame = got
    assert name == node and frame.kind in (frames.OUTPUTS, frames.END, frames.BATCH)
    assert type(frame.step) is int and sum(relay.intake.dropped.values()) == before


@pytest.mark.parametrize("node", ["g", "h"])
@given(data=st.data())
def test_a_node_acts_only_on_releases_that_give_it_exactly_its_inputs(loaded, node, data):
    _quiet()
    runtime = NodeRuntime(loaded, node, impl=None, endpoint="tcp/127.0.0.1:1")
    payload = data.draw(payloads | frame_arrays([frames.STEP, frames.STEPS, frames.REPLAY, frames.RESTORE,
                                                 frames.CHECKPOINT, frames.INIT]).map(frames.msgpack.packb)
                        | _from_the_server(node).map(lambda sent: sent[0])
                        | _from_the_server(node).map(lambda sent: sent[0]))
    try:
        frame = runtime.receiver.accept(False, payload)
    except frames.FrameError:
        return
    if frame is None:
        return  # a replay for another node, or a release of others (this node is not due)
    assert frame.kind in (frames.START, frames.STEP, frames.STEPS, frames.REPLAY, frames.ROLLBACK, frames.STOP,
                          frames.CHECKPOINT, frames.RESTORE, frames.INIT)
    if frame.kind == frames.RESTORE:
        assert frame.node == node and 0 <= frame.step < frames.MAX_STEP and 0 <= frame.index < frame.count
        assert math.isfinite(frame.t)
        return
    if frame.kind == frames.CHECKPOINT:
        assert 0 <= frame.step < frames.MAX_STEP
        return
    release = frame.release if frame.kind == frames.REPLAY else frame
    if release.kind == frames.INIT:
        assert math.isfinite(release.t0)
    if release.kind in (frames.STEP, frames.STEPS, frames.INIT):
        mine = release.inputs[node]
        spec = loaded.project.node(node)
        assert len(mine) == len(spec.input)
        assert all(type(v) in WIRE_TYPES[p.type] for v, p in zip(mine, spec.input))
    if release.kind == frames.STEP:
        assert math.isfinite(release.t) and release.h > 0
        assert node not in release.slopes  # this node holds its inputs: derivatives for it are refused
    if release.kind == frames.STEPS:  # base points a node can step between, in order, a bounded number
        times = release.times
        assert 2 <= len(times) <= frames.MAX_BATCH + 1 and all(math.isfinite(x) for x in times)
        assert all(a < b for a, b in zip(times, times[1:]))


@pytest.mark.parametrize("wrong", [w for w in _RELEASE_WRONGS if w != "field"])
@pytest.mark.parametrize("node", ["g", "h"])
@given(data=st.data())
def test_a_node_acts_on_its_servers_frame_only_when_nothing_in_it_is_wrong(loaded, node, wrong, data):
    """Each thing a frame on ``down`` can have wrong on its own (a kind the server does not send,
    a step or time out of range, an input of another type, an input too few or too many,
    derivatives for a node that holds its inputs, a state piece out of range, a replay of no
    release) is refused; one meant for other nodes is passed over; a right one is acted on."""
    payload, kind, _ = data.draw(_from_the_server(node, wrong))
    _quiet()
    runtime = NodeRuntime(loaded, node, impl=None, endpoint="tcp/127.0.0.1:1")
    frame = None
    try:
        frame = runtime.receiver.accept(False, payload)
    except frames.FrameError:
        got = "refused"
    else:
        got = "passed over" if frame is None else "acted on"
    expected = {None: "acted on", "others": "passed over"}.get(wrong, "refused")
    assert got == expected, f"{node}: a {frames.KIND_NAMES[kind]} with {wrong or 'nothing'} wrong was {got}"
    if frame is not None:
        assert frame.kind == kind


@given(data=st.data())
def test_a_node_that_interpolates_takes_only_finite_derivatives_of_its_float_inputs(data):
    # Per input the types msgpack yields for it: a Real, an Integer and a String port.
    types = ((float, int), (int,), (str,))
    payload = data.draw(payloads | frame_arrays([frames.STEP]).map(frames.msgpack.packb))
    try:
        frame = frames.check_release(frames.decode(payload), "g", types, interpolates=True)
    except frames.FrameError:
        return
    if frame.kind != frames.STEP:  # a START or a STEPS: releases too, with no derivatives
        return
    mine = frame.slopes.get("g")
    if mine is None:
        return
    assert type(mine) is list and len(mine) == len(types)
    for d, allowed in zip(mine, types):
        assert d is None or (float in allowed and 1 <= len(d) <= frames.MAX_SLOPE_ORDER
                             and all(type(x) in (int, float) and math.isfinite(x) for x in d))


def test_a_node_that_interpolates_takes_a_step_with_its_derivatives_and_refuses_them_otherwise():
    step = frames.decode(frames.encode(frames.STEP, 3, 0.3, 0.1, "free", {"g": [1.0, 2, "s"]}, [],
                                       {"g": [[0.5, -1.0, 2.0], None, None]}))
    types = ((float, int), (int,), (str,))
    assert frames.check_release(step, "g", types, interpolates=True) is step
    with pytest.raises(frames.FrameError, match="holds its inputs over a step"):
        frames.check_release(step, "g", types)
    for bad, why in (([[0.5], None], "not one entry per input"), ([None, [1.0], None], "takes no floats"),
                     ([[1.0, 2.0, 3.0, 4.0], None, None], "not 1 to 3 finite numbers"),
                     ([[math.inf], None, None], "not 1 to 3 finite numbers"), ([[], None, None], "not 1 to 3")):
        forged = frames.decode(frames.encode(frames.STEP, 3, 0.3, 0.1, "free", {"g": [1.0, 2, "s"]}, [], {"g": bad}))
        with pytest.raises(frames.FrameError, match=why):
            frames.check_release(forged, "g", types, interpolates=True)


def test_only_this_process_can_speak_as_the_local_key(loaded):
    # A LIVE frame from the network (anyone may write on `down`) is not liveliness news.
    runtime = NodeRuntime(loaded, "g", impl=None, endpoint="tcp/127.0.0.1:1")
    live = frames.encode(frames.LIVE, "_server", False)
    with pytest.raises(frames.FrameError, match="LIVE frame is not for a node"):
        runtime.receiver.accept(False, live)
    assert runtime.receiver.accept(True, live) == frames.Live(node="_server", alive=False)


def _gateway_connections(loaded) -> list[_Connection]:
    a, b = socket.socketpair()
    a.close(), b.close()
    return [_Connection(a, loaded.project.node(n), token=None) for n in ("g", "h")]


@given(payloads | frame_arrays([frames.START, frames.STEP, frames.STEPS, frames.STOP]).map(frames.msgpack.packb)
       | st.sampled_from(["g", "h"]).flatmap(_from_the_server).map(lambda sent: sent[0]))
def test_the_gateway_translates_only_releases_each_bridge_fmu_can_take(loaded, payload):
    conns = _gateway_connections(loaded)
    try:
        data = translate_release(payload, conns)
    except frames.FrameError:
        return
    frame = frames.decode(payload)
    for conn, out in data.items():
        magic, version, kind, _, length = gp.HEADER.unpack_from(out)
        assert magic == gp.MAGIC and length == len(out) - gp.HEADER.size
        if kind == gp.STEP:  # a STEP for a bridge FMU it gives inputs, each of its port's type
            k, t, h, _, values = gp.parse_step(out[gp.HEADER.size:])
            mine = frame.inputs[conn.node.nodeName]
            assert frame.kind == frames.STEP and len(values) == len(mine) == len(conn.node.input)
            assert all(type(v) in types for v, types in zip(mine, conn.input_types))
            assert 0 <= k < frames.MAX_STEP and math.isfinite(t) and h > 0


@pytest.mark.parametrize("wrong", [w for w in _RELEASE_WRONGS if w != "field"])
@given(data=st.data())
def test_the_gateway_passes_on_the_servers_release_only_when_nothing_in_it_is_wrong(loaded, wrong, data):
    """What a bridge FMU gets from a frame on ``down``: a right START or STOP goes to each, a right
    STEP to each bridge FMU it releases (g, or g and h); a frame with one thing wrong for one of
    them goes to none; other kinds, to none either (the gateway does not carry them)."""
    node = data.draw(st.sampled_from(["g", "h"]))
    payload, kind, _ = data.draw(_from_the_server(node, wrong))
    conns = _gateway_connections(loaded)
    try:
        got = {c.node.nodeName for c in translate_release(payload, conns)}
    except frames.FrameError:
        got = None
    if kind in (frames.START, frames.STOP) and wrong is None:
        assert got == {"g", "h"}
    elif kind == frames.STEP and wrong is None:
        assert node in got and got <= {"g", "h"}
    elif kind == frames.STEP and wrong == "others":
        assert node not in got
    elif kind in (frames.START, frames.STEP) and wrong in ("t", "step", "value", "ports", "slopes"):
        assert got is None, f"a {frames.KIND_NAMES[kind]} with its {wrong} wrong for {node} went to {got}"
    elif kind in (frames.START, frames.STEP, frames.STOP):
        raise AssertionError(f"no expectation for a {frames.KIND_NAMES[kind]} with {wrong} wrong")
    else:
        assert not got  # not a kind a bridge FMU takes: refused or passed over


@given(st.lists(st.integers(0, 40), max_size=6), st.integers(-(2 ** 63), 2 ** 64 - 1) | st.integers(-1, 8))
def test_a_bridge_fmus_outputs_are_labelled_only_as_the_answer_to_its_last_release(loaded, released, step):
    """A bridge FMU counts its steps; after n releases (STEPs at steps ``released``) only the
    outputs of its n-th step are taken, labelled as the answer to the last release (k + 1), or
    the start point's (0) before any release; any other count is out of turn."""
    conn = _gateway_connections(loaded)[0]
    for k in released:
        conn.releasing(k)
    label = conn.label(step)
    if step != len(released):
        assert label is None
    else:
        assert label == (released[-1] + 1 if released else 0)


@given(gateway_streams())
def test_the_gateway_framing_reads_a_frame_or_names_what_is_wrong(stream):
    a, b = socket.socketpair()
    try:
        b.settimeout(2.0)
        a.sendall(stream)  # a few hundred bytes at most: the socket buffer holds them
        a.shutdown(socket.SHUT_WR)
        while True:
            try:
                kind, payload = gp.read_frame(b)
            except (gp.ProtocolError, EOFError):
                return
            assert gp.HELLO <= kind <= gp.STOP and len(payload) <= gp.MAX_PAYLOAD
            for parse in (gp.parse_hello, gp.parse_outputs):
                try:
                    parse(payload)
                except gp.ProtocolError:
                    pass
    finally:
        a.close()
        b.close()


class _Lines:
    def __init__(self):
        self.lines: list[dict] = []

    def warning(self, event, **kw):
        self.lines.append({"event": event, **kw})


def test_the_drop_log_keeps_exact_counts_and_a_bounded_log():
    log = _Lines()
    drops = DropLog(log, full_per_sender=3, summary_every_s=3600)
    for i in range(100_000):
        drops.drop(("malformed", "wrong type", "not owner")[i % 3], f"frame {i}", i, sender=f"n{i % 4}")
    for i in range(5_000):  # senders a peer makes up: tracked up to a bound, then summarised
        drops.drop("unknown sender", "x", i, sender=f"made-up-{i}")
    drops.flush(0)
    assert drops.counts == {"malformed": 33_334, "wrong type": 33_333, "not owner": 33_333, "unknown sender": 5_000}
    assert len(log.lines) < 300
    summarised = sum(line.get("count", 0) for line in log.lines if line["event"] == "frames dropped")
    assert summarised + sum(1 for line in log.lines if line["event"] == "frame dropped") == 105_000


def test_a_logged_exception_carries_its_traceback_in_the_json_line(tmp_path):
    from hycosim.core import logs

    path = tmp_path / "x.log.jsonl"
    logs.configure(path)
    try:
        raise ValueError("the cause")
    except ValueError:
        structlog.get_logger("server").exception("internal error")
    line = json.loads(Path(path).read_text().splitlines()[-1])
    assert line["event"] == "internal error"
    assert "Traceback (most recent call last)" in line["exception"] and "ValueError: the cause" in line["exception"]


class _Queued:
    """An inbox that hands the relay what was queued, then nothing (as a step timeout would)."""

    def __init__(self, items: list[tuple[str, bytes]]):
        self.items = list(items)

    def recv(self, timeout: float) -> tuple[str, bytes] | None:
        return self.items.pop(0) if self.items else None


_UIDS = {node: uid for node, (uid, _) in _SENDERS.items() if node != "src"}  # the stepping nodes


@st.composite
def _answers(draw) -> tuple[str, bytes]:
    """Plausible BATCH frames for a batch released at point 20 over 10 base steps: each node's
    UID, its outputs' types, labels and numbers of steps near the right ones."""
    node = draw(st.sampled_from(sorted(_UIDS)))
    earlier = draw(st.lists(_OUTPUTS[node], min_size=8, max_size=10))
    frame = frames.encode(frames.BATCH, _UIDS[node], draw(st.sampled_from([20, 21, 22])), 0.3,
                          draw(_OUTPUTS[node]), earlier)
    return f"hycosim/recv/up/{node}", frame


@given(st.lists(_answers() | st.tuples(st.sampled_from(["hycosim/recv/up/clock", "hycosim/recv/up/g",
                                                        "hycosim/recv/up/src"]), payloads), max_size=8))
def test_a_batched_release_is_gathered_whole_from_each_nodes_answer_whatever_else_comes(relay, before):
    """Released at point 20 for 10 base steps, each node owes one BATCH labelled 21 with nine
    steps before its last. Whatever comes first (junk, other labels, other numbers of steps),
    the relay gathers point 30 with ten steps' outputs of each node, each of its ports' types,
    or stops the run on an END (a forged one cannot be told from a node's on an open network),
    a source's among them (its samples are taken on the way)."""
    from hycosim.master.run_state import ModelEnded as _ModelEnded, RunError

    relay.ledger.expect_all(20, 0.0)
    relay.ledger.released(sorted(_UIDS), 20, 0.0, count=10, batched=True, span=10)
    genuine = [(f"hycosim/recv/up/{node}", frames.encode(frames.BATCH, uid, 21, 0.3, *(
        [[0.0, 1.0], [[0.0, 1.0]] * 9] if node == "clock" else
        [[1.0, 2, True, "x", b"y"], [[1.0, 2, True, "x", b"y"]] * 9] if node == "g" else
        [[1.0], [[1.0]] * 9]))) for node, uid in _UIDS.items()]
    relay.inbox = _Queued([*before, *genuine])
    try:
        arrivals = relay.gather(30, 0.0)
    except (RunError, _ModelEnded):
        return
    assert set(arrivals) == set(_UIDS)
    spec = relay.project
    for node in _UIDS:
        outputs = spec.node(node).output
        for step_values in [*relay.ledger.earlier[node], relay.outputs[node]]:
            assert len(step_values) == len(outputs) and all(
                type(v) in WIRE_TYPES[p.type] for v, p in zip(step_values, outputs))
        assert len(relay.ledger.earlier[node]) == 9


@given(clean=st.booleans(), earlier=st.just([]) | st.lists(st.lists(st.floats(), max_size=2), max_size=2),
       message=st.text(max_size=40), step=st.integers(-2, 40) | st.integers(-(2 ** 63), 2 ** 64 - 1),
       t=st.floats(allow_nan=True, allow_infinity=True), last=st.none() | st.lists(st.floats(), max_size=2))
def test_a_source_stops_a_gathering_only_with_an_unclean_unbatched_end(relay, clean, earlier, message, step, t, last):
    """A source's END says it was stopped or failed, whatever point the run is gathering: then
    the run stops with the source's words and the run's step. Any other END from it (clean, with
    batch outputs or outputs where it ended, a step or time out of range) is dropped and counted,
    and the point is gathered."""
    from hycosim.master.relay import RunError

    relay.ledger.expect_all(30, 0.0)
    genuine = [(f"hycosim/recv/up/{node}", frames.encode(frames.OUTPUTS, uid, 30, 0.3, outs))
               for (node, uid), outs in zip(_UIDS.items(), ([0.0, 1.0], [1.0, 2, True, "x", b"y"], [1.0]))]
    relay.inbox = _Queued([("hycosim/recv/up/src", frames.encode(frames.END, 4, step, t, clean, message, earlier,
                                                                       last)),
                           *genuine])
    dropped = sum(relay.intake.dropped.values())
    valid = not clean and earlier == [] and last is None and 0 <= step < frames.MAX_STEP and math.isfinite(t)
    try:
        arrivals = relay.gather(30, 0.0)
    except RunError as exc:
        assert valid and str(exc).startswith("node 'src'")
        assert f"step {relay.point}" in str(exc) and sum(relay.intake.dropped.values()) == dropped
        return
    assert not valid and sum(relay.intake.dropped.values()) == dropped + 1
    assert set(arrivals) == set(_UIDS)


_PORTS_AND_VALUES = st.lists(st.sampled_from(list(PortType)), min_size=1, max_size=5).flatmap(
    lambda types: st.tuples(st.just(types), st.lists(
        st.sampled_from([1.5, 7, True, "s", b"\x00", [1, 2], None, {}]) | st.one_of(*_VALUE.values()),
        min_size=len(types), max_size=len(types))))


@given(_PORTS_AND_VALUES)
def test_the_servers_intake_a_nodes_release_check_and_a_checkpoint_name_the_same_value_of_a_wrong_type(given_):
    """Values for a node's ports reach three receivers: a node's outputs the server's intake, its
    inputs in a release the node, a checkpoint's values the server that resumes. Each takes the
    values exactly when every one is of its port's wire type, and otherwise names the first that
    is not."""
    from hycosim.core.schema import Node
    from hycosim.master.checkpoints import _wrong_values

    types, vals = given_
    wrong = next((i for i, (v, t) in enumerate(zip(vals, types)) if type(v) not in WIRE_TYPES[t]), None)
    ports = [{"name": f"p{i}", "type": t.value} for i, t in enumerate(types)]
    node = Node.model_validate({"nodeName": "g", "UID": 1, "model": "gain", "input": ports, "output": ports})
    _quiet()
    assert frames.first_misfit(vals, [WIRE_TYPES[t] for t in types]) == wrong
    try:
        Intake([node]).accept("g", frames.encode(frames.OUTPUTS, 1, 2, 0.1, vals))
        intake = None
    except Dropped as exc:
        assert exc.reason == "wrong type"
        intake = exc.detail
    release = frames.decode(frames.encode(frames.STEP, 3, 0.3, 0.1, "free", {"g": vals}, [], {}))
    try:
        frames.check_release(release, "g", tuple(WIRE_TYPES[t] for t in types))
        node_says = None
    except frames.FrameError as exc:
        node_says = str(exc)
    checkpoint = _wrong_values(vals, node.output)
    if wrong is None:
        assert intake is node_says is checkpoint is None
    else:
        assert intake.startswith(f"g.p{wrong} got {type(vals[wrong]).__name__} ")
        assert node_says == f"STEP 3 gives node 'g' a {type(vals[wrong]).__name__} for input {wrong}"
        assert checkpoint.startswith(f"p{wrong} holds {type(vals[wrong]).__name__} ")


_TYPED = {PortType.REAL: st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from([1e308, -1e308]),
          PortType.INTEGER: st.integers(-(2 ** 31), 2 ** 31 - 1) | st.sampled_from([2 ** 1100, -(2 ** 1100)]),
          PortType.BOOLEAN: st.booleans(),
          PortType.STRING: st.text(max_size=4), PortType.BINARY: st.binary(max_size=4)}


@st.composite
def _direct_outputs(draw):
    """Output ports, and one value per port of its type as a node's runtime makes it in process,
    maybe with one value that is no number (a model or runtime gone wrong)."""
    types = draw(st.lists(st.sampled_from(list(PortType)), min_size=1, max_size=5))
    vals = [draw(_TYPED[t]) for t in types]
    if draw(st.booleans()):
        vals[draw(st.integers(0, len(vals) - 1))] = draw(st.sampled_from(["1", None, b"\x00", [], {}, [1.0]]))
    return types, vals


@given(_direct_outputs())
def test_an_in_process_nodes_outputs_are_taken_and_noted_as_a_frames_are(given_):
    """In process the master checks a node's outputs with one sum where every port is a scalar
    number (Intake.check_direct): on values of their ports' types, and on ones that are no
    number, it takes, refuses and notes non-finite values exactly as the check of a frame does
    (a sum that overflows, holds an integer beyond a float's range or is no number falls back to
    that check)."""
    from hycosim.core.schema import Node

    types, vals = given_
    _quiet()
    ports = [{"name": f"p{i}", "type": t.value} for i, t in enumerate(types)]
    node = Node.model_validate({"nodeName": "g", "UID": 1, "model": "gain", "output": ports})
    verdicts = []
    for check in ("check_values", "check_direct"):
        intake = Intake([node])
        try:
            getattr(intake, check)("g", 4, 0.4, list(vals))
            verdicts.append((None, intake.non_finite))
        except Dropped as exc:
            verdicts.append((exc.detail, intake.non_finite))
    assert verdicts[0] == verdicts[1]
    wrong = next((i for i, (v, t) in enumerate(zip(vals, types)) if type(v) not in WIRE_TYPES[t]), None)
    assert (verdicts[1][0] is None) == (wrong is None)
    noted = {f"g.p{i}" for i, v in enumerate(vals) if type(v) is float and not math.isfinite(v) and
             (wrong is None or i < wrong)}
    assert set(verdicts[1][1]) == noted


def _same(a, b) -> bool:
    """Equal as the wire carries them (NaN equal to NaN; a named tuple as its fields)."""
    return frames.msgpack.packb(a) == frames.msgpack.packb(b)


@given(st.one_of(st.tuples(st.sampled_from(["clock", "g", "h", "src", "nobody"]) | names, payloads),
                 _from_a_node(), _from_a_node(None)), st.integers(-1, 41))
def test_the_flat_outputs_path_takes_exactly_what_the_intake_takes(loaded, sent, owed):
    """The barrier tries each answer on Intake.plain_outputs first: it must take the values of
    exactly the frames decode + accept take as a stepping node's OUTPUTS of the step it owes,
    noting the same non-finite values, and leave everything else to accept."""
    node, payload = sent[:2]
    _quiet()
    flat, whole = Intake(loaded.project.nodeLists), Intake(loaded.project.nodeLists)
    got = flat.plain_outputs(node, payload, owed)
    try:
        frame = whole.accept(node, payload)
    except Dropped:
        frame = None
    spec = loaded.project.node(node) if node in _SENDERS else None
    expected = (frame.values if frame is not None and frame.kind == frames.OUTPUTS and not spec.asynchronous
                and frame.step == owed else None)
    assert (got is None) == (expected is None) and _same(got, expected)
    if got is not None:
        assert flat.non_finite == whole.non_finite and flat.dropped == {}


@pytest.mark.parametrize("uid", [0, 2**63 - 1, 2**63, 2**64 - 1])
def test_the_flat_outputs_path_takes_a_real_nodes_own_outputs_whatever_its_uid(uid):
    """A node whose outputs are all real scalars is read by a decoder that checks its UID in C,
    as a literal, which msgspec takes only up to 2**63 - 1: a larger UID goes msgpack's way, and
    either way the node's own OUTPUTS of the step owed are taken and nothing else is."""
    from hycosim.core.schema import Node

    _quiet()
    node = Node.model_validate({"nodeName": "g", "UID": uid, "model": "gain",
                                "output": [{"name": "y", "type": "Real"}, {"name": "z", "type": "Real"}]})
    intake = Intake([node])
    own = frames.encode(frames.OUTPUTS, uid, 7, 0.7, [1.5, 2])
    assert intake.plain_outputs("g", own, 7) == [1.5, 2]
    other = uid - 1 if uid else 1
    for payload, step in ((own, 8), (frames.encode(frames.OUTPUTS, other, 7, 0.7, [1.5, 2]), 7),
                          (frames.encode(frames.OUTPUTS, uid, 7, 0.7, [1.5]), 7),
                          (frames.encode(frames.OUTPUTS, uid, 7, math.inf, [1.5, 2]), 7)):
        assert intake.plain_outputs("g", payload, step) is None
    noted = intake.plain_outputs("g", frames.encode(frames.OUTPUTS, uid, 7, 0.7, [math.nan, 2]), 7)
    assert math.isnan(noted[0]) and set(intake.non_finite) == {"g.y"}


@given(st.sampled_from([2**63 - 1, 2**63, 2**64 - 1]), st.data())
def test_the_flat_outputs_path_of_a_real_node_takes_what_the_intake_takes_whatever_its_uid(uid, data):
    """Garbage, OUTPUTS-shaped arrays and the node's own frames with one thing wrong, for a node
    of real outputs whose UID is either side of msgspec's literal limit: Intake.plain_outputs
    takes exactly what decode + accept take as its OUTPUTS of the step owed."""
    from hycosim.core.schema import Node

    _quiet()
    node = Node.model_validate({"nodeName": "g", "UID": uid, "model": "gain",
                                "output": [{"name": "y", "type": "Real"}, {"name": "z", "type": "Real"}]})
    number = st.floats(allow_nan=True, allow_infinity=True) | st.integers(-3, 3) | st.sampled_from(_ODD)
    # The node's own OUTPUTS of the step owed, with at most one thing wrong (half of them right).
    wrong = data.draw(st.sampled_from([None, None, None, None, "uid", "step", "t", "values"]))
    fields = [uid, 7, data.draw(st.floats(0, 10)), data.draw(st.lists(st.floats(), min_size=2, max_size=2))]
    if wrong is not None:
        at = ["uid", "step", "t", "values"].index(wrong)
        fields[at] = data.draw({"uid": st.sampled_from([uid - 1, 0, -1]), "step": st.sampled_from([6, -1, frames.MAX_STEP]),
                                "t": st.sampled_from([math.nan, math.inf, -math.inf]),
                                "values": st.lists(number, max_size=3)}[wrong])
    source = data.draw(st.sampled_from(["own", "own", "own", "garbage", "array"]))
    payload = (frames.encode(frames.OUTPUTS, *fields) if source == "own" else data.draw(
        payloads if source == "garbage" else frame_arrays([frames.OUTPUTS]).map(frames.msgpack.packb)))
    flat, whole = Intake([node]), Intake([node])
    got = flat.plain_outputs("g", payload, 7)
    try:
        frame = whole.accept("g", payload)
    except Dropped:
        frame = None
    expected = frame.values if frame is not None and frame.kind == frames.OUTPUTS and frame.step == 7 else None
    assert (got is None) == (expected is None) and _same(got, expected)
    if got is not None:
        assert flat.non_finite == whole.non_finite
    event("taken" if got is not None else "refused")


def _a_release(node: str):
    """Payloads on ``down`` for ``node``: anything, any STEP-shaped array, and what its server sends."""
    return (payloads | frame_arrays([frames.STEP]).map(frames.msgpack.packb)
            | _from_the_server(node).map(lambda sent: sent[0])
            | _from_the_server(node, None).map(lambda sent: sent[0]))


@st.composite
def _a_step(draw, node: str, drives: dict[str, tuple[str, ...]]) -> bytes:
    """A STEP for ``node`` in a mode of the run or another, naming the nodes the mode drives as its
    server does most of the time, else others, with or without slopes; its time and step size
    finite or not (the server's strategy rarely reaches a STEP the flat path takes in a mode)."""
    released = draw(st.sets(st.sampled_from(sorted(_RECEIVERS)))) | {node}
    inputs = {n: draw(_INPUTS[n]) for n in sorted(released)}
    mode = draw(st.sampled_from([*drives, "other"]))
    exact = list(drives.get(mode, ()))
    driven = draw(st.sampled_from([exact, exact, exact, [], ["h"], ["g"], ["g", "h"], ["h", "h"], [7]]))
    slopes = draw(st.sampled_from([{}, {}, {}, {"clock": [0.1]}, {node: [0.1] * len(inputs[node])}]))
    fields = [draw(st.integers(0, 40)), draw(st.floats(0, 10)), draw(st.floats(1e-4, 1.0))]
    if draw(st.sampled_from([False, False, False, True])):  # one of them out of range
        at = draw(st.integers(0, 2))
        fields[at] = draw(st.sampled_from([[-1, frames.MAX_STEP], [math.nan, math.inf], [0.0, -0.1, math.nan]][at]))
    return frames.msgpack.packb([frames.VERSION, frames.STEP, *fields, mode, inputs, driven, slopes])


@pytest.mark.parametrize("events", [False, True], ids=["no events", "two events driving h"])
@pytest.mark.parametrize("node", ["g", "h"])
@given(data=st.data())
def test_the_flat_release_path_passes_exactly_what_a_node_accepts(loaded, loaded_events, events, node, data):
    """A node stepping in a mode (driven or not) tries each release on ReleaseReader.plain first:
    it must pass exactly the STEPs that the node's decode + check_release pass (equal to what
    they give) and that leave it in that mode and state, naming the nodes the mode drives as its
    server names them; nothing else, and nothing before the node has a mode of the run."""
    _quiet()
    project = loaded_events if events else loaded
    receiver = NodeRuntime(project, node, impl=None, endpoint="tcp/127.0.0.1:1").receiver
    drives = project.project.driven_in()
    # Half the time a STEP drawn for this test: in a union with the four of _a_release, a fifth.
    payload = data.draw(_a_step(node, drives) if data.draw(st.sampled_from([True, False])) else _a_release(node))
    mode = data.draw(st.sampled_from([None, "free", "grasped", "held", "other"]))
    driven = data.draw(st.booleans())
    if data.draw(st.sampled_from([True, True, True, False])):  # mostly the node in the state a STEP leaves it in
        try:
            step = frames.decode(payload)
        except frames.FrameError:
            step = None
        if step is not None and step.kind == frames.STEP:
            mode, driven = step.mode, node in step.driven
    got = receiver.releases.plain(payload, mode, driven)
    try:
        frame = receiver.accept(False, payload)
    except frames.FrameError:
        frame = None
    expected = frame if (frame is not None and frame.kind == frames.STEP and frame.mode == mode and mode in drives
                         and list(frame.driven) == list(drives[mode]) and (node in frame.driven) == driven) else None
    assert (got is None) == (expected is None)
    event("flat" if got is not None else "whole way")
    if got is not None:
        release, mine = got, got.inputs.mine
        assert _same([release.step, release.t, release.h, release.mode, release.driven, mine],
                     [expected.step, expected.t, expected.h, expected.mode, expected.driven, expected.inputs[node]])
        assert node not in expected.slopes


@pytest.mark.parametrize("node", ["g", "h"])
def test_a_server_release_in_each_mode_takes_the_flat_path_of_the_state_it_leaves(loaded_events, node):
    """What the flat path takes in a mode is what the server sends in it: a release encoded as the
    barrier encodes it, with the coordinator in each mode of the run, passes the flat decoder of a
    node stepping in that mode (driven where the mode drives it) and no other mode's."""
    _quiet()
    from hycosim.master.coordinator import Coordinator

    receiver = NodeRuntime(loaded_events, node, impl=None, endpoint="tcp/127.0.0.1:1").receiver
    coordinator = Coordinator(loaded_events.project.events, loaded_events.guards)
    inputs = {"g": [0.5], "h": [0.25, 3, True]}
    modes = loaded_events.project.modes()
    assert modes == ["free", "grasped", "held"]
    for mode in modes:
        coordinator.mode = mode
        driven = coordinator.driven_nodes()
        payload = frames.encode(frames.STEP, 4, 0.4, 0.1, mode, inputs, driven, {})
        release = receiver.releases.plain(payload, mode, node in driven)
        assert release is not None and release.step == 4 and _same(release.inputs.mine, inputs[node])
        assert (node in driven) == (node == "h" and mode != "free")
        for other in modes:
            if other != mode:
                assert receiver.releases.plain(payload, other, node in driven) is None
                assert receiver.releases.plain(payload, other, node not in driven) is None
        assert receiver.releases.plain(payload, mode, node not in driven) is None


def _but_the_others(payload: bytes, node: str) -> bytes | None:
    """The STEP in ``payload`` with every other node's entry of inputs and slopes taken out, the
    rest byte for byte (None if msgspec does not read it as a STEP)."""
    from hycosim.node.releases import _STEP

    try:
        wire = _STEP.decode(payload)
    except Exception:
        return None
    wire.inputs = {n: raw for n, raw in wire.inputs.items() if n == node}
    wire.slopes = {n: raw for n, raw in wire.slopes.items() if n == node}
    return msgspec.msgpack.encode(wire)


@pytest.mark.parametrize("node", ["g", "h"])
@given(data=st.data())
def test_a_node_reads_a_step_as_decode_reads_it_without_the_other_nodes_entries(loaded, node, data):
    """A node reads a release's own entry alone (node/releases.py): any frame it takes, it takes
    as frames.decode + check_release take the same frame with the other nodes' entries taken out;
    a frame that is no STEP exactly as they do; and a STEP they take it refuses only for a name
    that is no string (an entry's key, a driven node)."""
    _quiet()
    receiver = NodeRuntime(loaded, node, impl=None, endpoint="tcp/127.0.0.1:1").receiver
    payload = data.draw(_a_release(node))

    def whole(p: bytes):
        try:
            return receiver.accept_frame(False, frames.decode(p))
        except frames.FrameError:
            return "refused"

    try:
        mine = receiver.accept(False, payload)
    except frames.FrameError:
        mine = "refused"
    theirs = whole(payload)
    is_step = mine != "refused" and mine is not None and mine.kind == frames.STEP
    if not is_step:
        try:
            is_step = frames.decode(payload).kind == frames.STEP
        except frames.FrameError:
            pass
    if not is_step:
        assert _same(mine, theirs)
        return
    if mine == "refused":
        if theirs != "refused":  # they take it or pass it over: it names something by no string
            step = frames.decode(payload)
            assert any(type(n) is not str for n in [*step.inputs, *step.slopes, *step.driven])
        return
    assert _same(mine, whole(_but_the_others(payload, node)))


class _Float(float):
    """A subclass of float, as NumPy's float64 is: msgspec does not pack it, msgpack does."""


def _raw_map(entries: dict[str, bytes]) -> bytes:
    """A msgpack map of the given keys to values packed already (which may be no msgpack a
    Python packer would write)."""
    return bytes([0x80 | len(entries)]) + b"".join(frames.msgpack.packb(k) + v for k, v in entries.items())


@pytest.mark.parametrize("garbage", [b"\xa2\xff\xfe", b"\x81\x91\x01\x01", b"\xd5\xff\x00\x00"],
                         ids=["a string of no UTF-8", "a map keyed by an array", "a timestamp of 2 bytes"])
def test_a_node_steps_on_a_release_whatever_another_nodes_entry_holds(loaded, garbage):
    """Another node's entry is skipped, not judged: a node takes its own inputs from a STEP whose
    entry for another node holds what msgpack-python will not decode (so frames.decode refuses
    the whole frame); an entry that is no msgpack at all still makes the frame refused."""
    _quiet()
    receiver = NodeRuntime(loaded, "g", impl=None, endpoint="tcp/127.0.0.1:1").receiver
    head = frames.msgpack.packb([frames.VERSION, frames.STEP, 3, 0.3, 0.1, "free"])[1:]
    tail = frames.msgpack.packb([])  # driven
    for other in (garbage, b"\xc1", b"\xdb\xff\xff\xff\xff"):
        payload = b"\x99" + head + _raw_map({"g": frames.msgpack.packb([0.25]), "h": other}) + tail + _raw_map({})
        if other is garbage:
            with pytest.raises(frames.FrameError):
                frames.decode(payload)
            frame = receiver.accept(False, payload)
            assert frame.kind == frames.STEP and frame.inputs == {"g": [0.25]} and frame.step == 3
            release = receiver.releases.plain(payload, "free", False)
            assert release.step == 3 and release.inputs.mine == (0.25,)
        else:  # an opcode msgpack never uses, or a string longer than the frame
            with pytest.raises(frames.FrameError):
                receiver.accept(False, payload)
            assert receiver.releases.plain(payload, "free", False) is None


@given(st.lists(frame_arrays(), min_size=1, max_size=8))
def test_frames_packed_by_threads_at_once_are_each_what_msgpack_packs(arrays):
    """frames.encode packs with one msgspec Encoder for every thread (Zenoh's threads pack frames
    too), and with msgpack what msgspec does not take: whatever several threads pack at once,
    among frames neither packs (an integer beyond 64 bits, an object) and values only msgpack
    packs (a subclass of float), each frame is the bytes msgpack.packb gives it, and a refused one
    raises."""
    fields = [(a[1], a[2:]) for a in arrays] + [(frames.OUTPUTS, [1, 2 ** 64]), (frames.STEP, [object()]),
                                                (frames.OUTPUTS, [1, 2, 0.5, [_Float(0.25)]])]
    expected = []
    for kind, rest in fields:
        try:
            expected.append(frames.msgpack.packb([frames.VERSION, kind, *rest], use_bin_type=True))
        except (TypeError, OverflowError, ValueError):
            expected.append(None)
    wrong: list[str] = []

    def pack_all() -> None:
        for _ in range(20):
            for (kind, rest), want in zip(fields, expected):
                try:
                    got = frames.encode(kind, *rest)
                except (TypeError, OverflowError, ValueError):
                    got = None
                if got != want:
                    wrong.append(f"{kind!r}: {frames.short(rest)}")

    threads = [threading.Thread(target=pack_all) for _ in range(3)]
    for thread in threads:
        thread.start()
    pack_all()
    for thread in threads:
        thread.join(timeout=30)
    assert not wrong and expected[-3:-1] == [None, None] and expected[-1] is not None
