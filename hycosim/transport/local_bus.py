"""Frames between the server's master and nodes hosted in the same process: direct calls, no sockets.

An in-process run (``hycosim run FILE --in-process``) hosts the relay and every node in one
thread. The master's release is a call: :meth:`LocalBus.release` decodes the frame once and
hands it to each node, which steps its model there and then and queues its answer for the
master. When the master next reads its inbox, the answers are already there; an empty inbox
means no node will answer any more (nothing else runs), so :meth:`LocalInbox.recv` returns
None at once rather than waiting out a timeout.

The frames are the distributed run's, byte for byte: the master encodes what it releases,
and a node's answer is encoded and goes through the master's intake as one from the network
would. Only the transport is gone, so an in-process run records the values a distributed run
of the same project records.

A macro step needs no frame at all: a node hosted here also gives the bus its
:data:`DirectStep`, which the master calls with the inputs it routed and which returns the
node's outputs, as its model's step and its runtime's output check make them. Frames still
carry everything else (the START, the initialisation, rollbacks, the STOP), and the rare
answer that is no outputs: a node whose model ended the run or failed sends its END as over
the network, and its direct step returns None.
"""

from __future__ import annotations

import collections
from collections.abc import Callable
from typing import Any

from hycosim.core import frames
from hycosim.transport.inbox import LOCAL
from hycosim.transport.keys import ProjectKeys

# A node hosted in process: called with each frame the master releases (decoded once for all).
Deliver = Callable[[frames.Frame], None]
# A node's macro step without frames: (k, t, h, mode, driven, inputs) → its outputs at t + h, in
# port order and checked by the node as it checks what it sends; None when its model ended the
# run or failed instead (its END is in the master's inbox then).
DirectStep = Callable[[int, float, float, str, bool, list[Any]], "list[Any] | None"]


class LocalInbox:
    """The master's inbox in process: what the hosted nodes sent, in order (the interface of
    :class:`hycosim.transport.inbox.Inbox`)."""

    def __init__(self) -> None:
        self._queue: collections.deque[tuple[str, bytes]] = collections.deque()
        self._waits = {"queued": 0, "polled": 0, "slept": 0}

    @property
    def waits(self) -> dict[str, int]:
        """How the frames so far were had: all ``queued`` (nothing is waited for in process)."""
        return dict(self._waits)

    def put(self, key: str, payload: bytes) -> None:
        """Queue a frame a node sent on ``key`` (its ``up`` key)."""
        self._queue.append((key, payload))

    def inject(self, payload: bytes) -> None:
        """Queue a local event (a node attaching or leaving); ``recv`` returns it under :data:`LOCAL`."""
        self._queue.append((LOCAL, payload))

    def recv(self, timeout: float) -> tuple[str, bytes] | None:
        """The next frame as (key, payload), or None when none is queued: in process nothing
        else runs while the master waits, so nothing would come however long it waited."""
        if not self._queue:
            return None
        self._waits["queued"] += 1
        return self._queue.popleft()

    def close(self) -> None:
        """Drop what is still queued."""
        self._queue.clear()


class LocalPublisher:
    """Publishes on one key in process (the interface of :class:`hycosim.transport.session.FramePublisher`)."""

    def __init__(self, send: Callable[[bytes], None]) -> None:
        self.put = send


class LocalBus:
    """The master and the nodes of one in-process run.

    A node attaches with its deliver function (as a Zenoh node declares its liveliness token:
    the master learns of it from a LIVE event), publishes on its ``up`` key through
    :meth:`publisher`, and leaves after the run's STOP. The master reads :attr:`inbox` and
    releases through :attr:`release`.
    """

    def __init__(self, project: str) -> None:
        self.keys = ProjectKeys(project)
        self.inbox = LocalInbox()
        self.release = LocalPublisher(self._release)
        self._nodes: dict[str, Deliver] = {}
        self.direct: dict[str, DirectStep] = {}  # the nodes that can be stepped by a call
        self.undecodable = 0  # releases that were no frame (the master writes none: a bug, counted)

    @property
    def nodes(self) -> list[str]:
        """The nodes attached, in the order they attached."""
        return list(self._nodes)

    def attach(self, node: str, deliver: Deliver, step: DirectStep | None = None) -> None:
        """Host ``node``: every frame the master releases from now on is given to ``deliver``;
        ``step``, if given, takes its macro steps as calls."""
        self._nodes[node] = deliver
        if step is not None:
            self.direct[node] = step
        self.inbox.inject(frames.encode(frames.LIVE, node, True))

    def leave(self, node: str) -> None:
        """``node`` takes no more frames; the master hears that it left."""
        self.direct.pop(node, None)
        if self._nodes.pop(node, None) is not None:
            self.inbox.inject(frames.encode(frames.LIVE, node, False))

    def publisher(self, node: str) -> LocalPublisher:
        """Where ``node`` sends its frames: the master's inbox, under the node's ``up`` key."""
        key, put = self.keys.up(node), self.inbox.put
        return LocalPublisher(lambda payload: put(key, payload))

    def _release(self, payload: bytes) -> None:
        # Decoded once for all nodes; each checks it as a node checks a frame from the network.
        try:
            frame = frames.decode(payload)
        except frames.FrameError:
            self.undecodable += 1
            return
        for deliver in list(self._nodes.values()):
            deliver(frame)
