"""A node's end of a transport (hycosim.transport.node_side) and the runtime's one handler of
the master's frames: what a Zenoh node pulls and what an in-process master pushes go through
NodeRuntime.handle alike. Here the in-process end, frame by frame, reaches phases an
in-process run never takes (a state restored in pieces), as a Zenoh node does."""

from __future__ import annotations

import inspect
from types import SimpleNamespace

import pytest

from hycosim.core import frames
from hycosim.core.config import load_project
from hycosim.node.interface import pack_state
from hycosim.node.loader import load_node
from hycosim.node.in_process import HostedNode
from hycosim.transport.local_bus import LocalBus
from hycosim.transport.node_side import LocalNodeLink, NodeLink, ZenohNodeLink
from hycosim.transport.session import LOW_LATENCY_MAX_FRAME
from tests.helpers import write_project


def test_both_ends_implement_the_node_link_protocol():
    wanted = {name for name, _ in inspect.getmembers(NodeLink) if not name.startswith("_")}
    assert wanted == {"send", "receive", "waits", "close"}
    for cls in (ZenohNodeLink, LocalNodeLink):
        assert wanted <= set(dir(cls)), cls


@pytest.fixture
def hosted(tmp_path):
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "clock", "UID": 1, "model": "ramp", "output": ["y", "v"]},
        {"nodeName": "g", "UID": 2, "model": "gain", "parameters": {"k": 2.0}, "input": ["u"], "output": ["y"]},
    ], [{"from": "clock.y", "to": "g.u"}], cosim={"stepSize": 0.1, "stopTime": 1.0})
    loaded = load_project(cfg)
    spec = loaded.project.node("g")
    runtime = HostedNode(loaded, "g", load_node(spec, tmp_path, loaded.project.coSimulation), endpoint="")
    bus = LocalBus(loaded.project.projectName)
    runtime.host(bus)
    yield runtime, bus
    runtime.close()


def _sent(bus: LocalBus) -> list[frames.Frame]:
    """What the node sent the master since last asked (the attach's LIVE left out)."""
    out = []
    while (msg := bus.inbox.recv(0.0)) is not None:
        frame = frames.decode(msg[1])
        if frame.kind != frames.LIVE or not frame.alive:
            out.append(frame)
    return out


def _start(checkpoint: bool = False) -> bytes:
    return frames.encode(frames.START, "run", 0.0, 0.1, 0.0, None, {"checkpoint": checkpoint})


def _step(k: int, u: float) -> bytes:
    return frames.encode(frames.STEP, k, 0.1 * k, 0.1, "free", {"g": [u]}, [], {})


def test_the_in_process_end_sends_into_the_masters_inbox_and_leaves_at_stop(hosted):
    runtime, bus = hosted
    assert isinstance(runtime.link, LocalNodeLink) and runtime.link.receive(5.0) is None  # nothing is pulled
    runtime.deliver(frames.decode(_start()))
    hello, outputs = _sent(bus)
    assert hello.kind == frames.HELLO and (outputs.kind, outputs.step, outputs.values) == (frames.OUTPUTS, 0, [0.0])
    runtime.deliver(frames.decode(_step(0, 1.5)))
    [outputs] = _sent(bus)
    assert (outputs.step, outputs.values) == (1, [3.0])
    runtime.deliver(frames.decode(frames.encode(frames.STOP, 1, frames.STOP_COMPLETED)))
    [left] = _sent(bus)
    assert (left.kind, left.node, left.alive) == (frames.LIVE, "g", False) and "g" not in bus.nodes


def test_a_state_restored_in_pieces_goes_through_the_same_handler(hosted):
    runtime, bus = hosted
    runtime.deliver(frames.decode(_start(checkpoint=True)))
    runtime.deliver(frames.decode(_step(0, 1.0)))
    _sent(bus)
    state = pack_state({"y": 7.0})
    first, second = state[:3], state[3:]
    runtime.deliver(frames.decode(frames.encode(frames.RESTORE, "g", 5, 0.5, 0, 2, first, {})))
    assert _sent(bus) == []  # one piece of two: nothing to answer yet
    runtime.deliver(frames.decode(frames.encode(frames.RESTORE, "g", 5, 0.5, 1, 2, second, {})))
    hello, outputs = _sent(bus)
    assert hello.kind == frames.HELLO and (outputs.step, outputs.t, outputs.values) == (5, 0.5, [7.0])
    runtime.deliver(frames.decode(_step(5, 4.0)))  # and steps on from the restored point
    [outputs] = _sent(bus)
    assert (outputs.step, outputs.values) == (6, [8.0]) and runtime.steps == 6


def test_a_state_that_comes_in_part_is_dropped_and_the_node_goes_on(hosted):
    runtime, bus = hosted
    runtime.deliver(frames.decode(_start(checkpoint=True)))
    runtime.deliver(frames.decode(_step(0, 1.0)))
    _sent(bus)
    runtime.deliver(frames.decode(frames.encode(frames.RESTORE, "g", 5, 0.5, 0, 2, b"\x81", {})))
    runtime.deliver(frames.decode(_step(1, 2.0)))  # the second piece never came
    assert runtime.drops.counts == {"not a release": 1} and runtime.failure is None
    runtime.deliver(frames.decode(_step(1, 2.0)))
    [outputs] = _sent(bus)
    assert (outputs.step, outputs.values) == (2, [4.0])


def test_the_zenoh_end_receives_what_the_server_releases_and_nothing_once_closed(tmp_path):
    """Over a real router on loopback: a frame on the node's ``down`` key is received as it was
    put; once closed, the link gives None at once (its inbox is gone), as before it opened."""
    import time

    from hycosim.transport.keys import ProjectKeys
    from hycosim.transport.session import open_session, router_config
    from tests.helpers import free_endpoint

    endpoint = free_endpoint()
    cfg = write_project(tmp_path / "p.json", [
        {"nodeName": "g", "UID": 1, "model": "gain", "input": ["u"], "output": ["y"]}],
        cosim={"stepSize": 0.1, "stopTime": 1.0, "attachTimeout": 5.0})
    loaded = load_project(cfg)
    router = open_session(router_config(endpoint), endpoint)
    try:
        link = ZenohNodeLink.open(loaded, "g", endpoint)
        try:
            release = _step(3, 1.5)
            deadline = time.monotonic() + 10.0
            got = None
            while got is None and time.monotonic() < deadline:  # until the node's subscription is known
                router.put(ProjectKeys(loaded.project.projectName).down, release)
                got = link.receive(0.2)
                while got is not None and got[1] != release:  # the server token's news, if any
                    got = link.receive(0.2)
            assert got is not None and got[1] == release
        finally:
            link.close()
        started = time.monotonic()
        assert link.receive(5.0) is None and time.monotonic() - started < 1.0
        link.close()  # twice: nothing left to close
    finally:
        router.close()


class _ScriptedLink:
    """A node's end of a link that gives the node ``script`` (payloads as the server puts them on
    ``down``) and keeps what the node sends: the Zenoh node's loop without a network."""

    def __init__(self, script: list[bytes]):
        self._script, self.sent = iter(script), []
        self.session = type("Session", (), {"close": lambda self: None})()
        self.waits = None
        self.over = "scripted"  # what ZenohNodeLink.open says it connected to
        # What the flat path sends its outputs through (ZenohNodeLink.publisher).
        self.publisher = SimpleNamespace(unchecked_put=self.send, limit=LOW_LATENCY_MAX_FRAME)

    def receive(self, timeout: float):
        return "hycosim/p/down", next(self._script)

    def send(self, payload: bytes) -> None:
        self.sent.append(payload)

    def close(self) -> None:
        pass


def _run_scripted(monkeypatch, tmp_path, impl, script: list[bytes], events: list[dict] | None = None
                  ) -> list[frames.Frame]:
    """What a Zenoh node of the gain ``g`` sends over :class:`_ScriptedLink`, decoded (``events``:
    the project's, on a ramp ``c`` that feeds ``g``, which the script never steps)."""
    from hycosim.node import over_zenoh

    gain = {"nodeName": "g", "UID": 1, "model": "gain", "parameters": {"k": 0.5, "b": 1.0}, "input": ["u"],
            "output": ["y"]}
    nodes = [gain] if not events else [gain, {"nodeName": "c", "UID": 2, "model": "ramp", "output": ["y", "v"]}]
    cfg = write_project(tmp_path / "p.json", nodes, [{"from": "c.y", "to": "g.u"}] if events else None,
                        events=events, cosim={"stepSize": 0.1, "stopTime": 1.0})
    loaded = load_project(cfg)
    link = _ScriptedLink(script)
    monkeypatch.setattr(over_zenoh.ZenohNodeLink, "open", classmethod(lambda cls, *args, **kwargs: link))
    over_zenoh.ZenohNode(loaded, "g", impl, "tcp/127.0.0.1:1").run()
    return [frames.decode(p) for p in link.sent]


def _counted_gain(calls: dict[str, int], modes: list[tuple[str, bool]] | None = None):
    """A gain that counts its steps by its list step (``calls["listed"]``) and through step()
    (``calls["step"]``, counted on the instance: the class's step stays the gain's own, so that
    the list step is offered), and keeps each mode it is told of in ``modes``."""
    from hycosim.node.reference.gain import Gain

    class Counted(Gain):
        def listed_step(self, inputs, outputs):
            stepped = super().listed_step(inputs, outputs)

            def step(t, h, values):
                calls["listed"] += 1
                return stepped(t, h, values)
            return step if stepped is not None else None

        def set_mode(self, mode, driven):
            if modes is not None:
                modes.append((mode, driven))
            super().set_mode(mode, driven)

    gain = Counted()
    through_step = gain.step

    def step(t, h, inputs):
        calls["step"] += 1
        through_step(t, h, inputs)
    gain.step = step
    return gain


def _dicts_gain():
    """A gain stepped through step() and outputs() alone (it offers no list step)."""
    from hycosim.node.reference.gain import Gain

    class Dicts(Gain):
        def listed_step(self, inputs, outputs):
            return None
    return Dicts()


def test_a_zenoh_node_steps_a_model_on_lists_where_it_can_as_it_steps_it_through_dicts(monkeypatch, tmp_path):
    """Over Zenoh every plain release steps a model that offers listed_step by it (no dict either
    way): the gain's outputs are the same frames, byte for byte in their values, as stepped
    through step() and outputs(), its parameters tuned between steps included; and every step
    but the first went through the listed call (the first release enters the run's mode, which
    the whole way tells the model)."""
    calls = {"listed": 0, "step": 0}
    script = [frames.encode(frames.START, "run", 0.0, 0.1, 0.0, None, {})]
    for k in range(6):
        if k == 3:
            script.append(frames.encode(frames.TUNE, "g", 3, 0.3, {"k": -2.0}))
        script.append(frames.encode(frames.STEP, k, 0.1 * k, 0.1, "free",
                                    {"g": [0.25 * k if k % 2 else k], "h": [9.0]}, [], {}))
    script.append(frames.encode(frames.STOP, 6, "completed"))
    listed = _run_scripted(monkeypatch, tmp_path, _counted_gain(calls), script)
    through_dicts = _run_scripted(monkeypatch, tmp_path, _dicts_gain(), script)
    assert calls == {"listed": 5, "step": 1}
    outputs = [f for f in listed if f.kind == frames.OUTPUTS]
    assert [(f.step, f.values) for f in outputs] == [(f.step, f.values) for f in through_dicts
                                                     if f.kind == frames.OUTPUTS]
    assert [f.values for f in outputs][1:] == [[0.5 * 0.0 + 1.0], [0.5 * 0.25 + 1.0], [0.5 * 2 + 1.0],
                                               [-2.0 * 0.75 + 1.0], [-2.0 * 4 + 1.0], [-2.0 * 1.25 + 1.0]]
    assert all(type(v) is float for f in outputs for v in f.values)


def test_a_zenoh_node_takes_the_flat_path_again_after_each_switch_of_mode(monkeypatch, tmp_path):
    """Over Zenoh a release that enters a mode (the run's first, an event's, free running
    again) goes the whole way, which tells the model its mode; the releases after it in that
    mode take the flat path (the model's list step) again: the model is told of each switch
    once, and its outputs are those stepped through step() and outputs() all the way."""
    calls: dict[str, int] = {"listed": 0, "step": 0}
    modes: list[tuple[str, bool]] = []
    events = [{"name": "hold", "when": "c.y > 1", "drives": "g", "until": "c.y > 2"},
              {"name": "watch", "when": "c.v > 1", "drives": "c", "until": "c.v > 2"}]
    script = [frames.encode(frames.START, "run", 0.0, 0.1, 0.0, None, {})]
    for k, (mode, driven) in enumerate([("free", []), ("free", []), ("hold", ["g"]), ("hold", ["g"]),
                                        ("hold", ["g"]), ("watch", ["c"]), ("watch", ["c"]), ("free", []),
                                        ("free", [])]):
        script.append(frames.encode(frames.STEP, k, 0.1 * k, 0.1, mode, {"g": [0.5 * k]}, driven, {}))
    script.append(frames.encode(frames.STOP, 9, "completed"))
    flat = _run_scripted(monkeypatch, tmp_path, _counted_gain(calls, modes), script, events)
    through_dicts = _run_scripted(monkeypatch, tmp_path, _dicts_gain(), script, events)
    assert modes == [("free", False), ("hold", True), ("watch", False), ("free", False)]
    assert calls == {"listed": 5, "step": 4}
    outputs = [(f.step, f.values) for f in flat if f.kind == frames.OUTPUTS]
    assert len(outputs) == 10 and outputs == [(f.step, f.values) for f in through_dicts if f.kind == frames.OUTPUTS]


def test_the_gain_steps_on_lists_only_where_its_ports_and_its_step_are_its_own(monkeypatch, tmp_path):
    """Gain.listed_step: for input ``u`` and a real scalar ``y`` a call that does what step() and
    outputs() do; None for any other ports (an integer y, an array, another input), and for a
    subclass that changes step() or outputs(), which a node over Zenoh then steps through them."""
    from hycosim.core.schema import Port
    from hycosim.node.reference.gain import Gain

    gain = Gain()
    gain.k, gain.b, gain.work_s, gain.y = 3.0, -1.0, 0.0, 0.0
    step = gain.listed_step(["u"], [Port(name="y")])
    assert step(0.0, 0.1, (2,)) == [5.0] and gain.y == 5.0 and gain.outputs() == {"y": 5.0}
    for inputs, outputs in ((["v"], [Port(name="y")]), (["u"], [Port(name="y", type="Integer")]),
                            (["u"], [Port(name="y", shape=[2])]), (["u", "w"], [Port(name="y")])):
        assert gain.listed_step(inputs, outputs) is None

    class Doubled(Gain):
        def step(self, t, h, inputs):
            super().step(t, h, inputs)
            self.y *= 2

    class Offset(Gain):
        def outputs(self):
            return {"y": self.y + 100.0}

    assert Doubled().listed_step(["u"], [Port(name="y")]) is None
    assert Offset().listed_step(["u"], [Port(name="y")]) is None
    script = [frames.encode(frames.START, "run", 0.0, 0.1, 0.0, None, {}),
              frames.encode(frames.STEP, 0, 0.0, 0.1, "free", {"g": [2.0]}, [], {}),
              frames.encode(frames.STOP, 1, "completed")]
    sent = _run_scripted(monkeypatch, tmp_path, Doubled(), script)
    assert [f.values for f in sent if f.kind == frames.OUTPUTS] == [[1.0], [2 * (0.5 * 2.0 + 1.0)]]
