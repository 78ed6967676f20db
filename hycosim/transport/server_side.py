"""How the relay's frames travel: over a Zenoh router session, or by calls in one process.

The relay's loop reads one inbox and releases through one publisher; it learns of nodes
attaching and leaving as LIVE events in that inbox. A transport gives it those two, and
whatever else a network needs (the server's liveliness token, the status queryable), and
takes them down after the run.
"""

from __future__ import annotations

import json
from types import MappingProxyType
from typing import Any, Callable, Mapping, Protocol

import zenoh

from hycosim.core import frames
from hycosim.transport.inbox import Inbox
from hycosim.transport.keys import SERVER_TOKEN, ProjectKeys
from hycosim.transport.local_bus import DirectStep, LocalBus
from hycosim.transport.session import FramePublisher
from hycosim.transport.answer_budget import AnswerBudget


class RelayInbox(Protocol):
    """Where the relay reads everything its nodes send, and the news of them attaching and
    leaving (:class:`hycosim.transport.inbox.Inbox`, or the local bus's)."""

    waits: dict[str, int]  # how each read got its frame (queued, polled, slept)

    def recv(self, timeout: float) -> tuple[str, bytes] | None:
        """The next frame as (key, payload) within ``timeout`` seconds, or None; LIVE news
        under the key ``inbox.LOCAL``."""

    def close(self) -> None:
        """Stop reading: nothing more is taken in."""


class Publisher(Protocol):
    """Where the relay's releases, starts and stops go to every node."""

    def put(self, payload: bytes) -> None:
        """Send one frame to every node (FrameTooLarge where the transport cannot carry it)."""


class Transport(Protocol):
    """What the relay is given to reach its nodes."""

    #: The Zenoh session a gateway for bridge FMUs joins, or None where there is none.
    session: zenoh.Session | None
    #: The nodes whose macro steps are calls rather than frames (in process), by name.
    direct: Mapping[str, DirectStep]
    #: Whether anyone can ask the run's status (the relay keeps each point's values for it).
    serves_status: bool

    def open(self, keys: ProjectKeys, polls: bool, low_latency: bool,
             status: Callable[[int | None], dict[str, Any]], answers: AnswerBudget) -> tuple[RelayInbox, Publisher]:
        """Declare what the run needs; return the inbox and the release publisher."""
        ...

    def close(self) -> None:
        """Undeclare what :meth:`open` declared (the run's records are closed by then)."""
        ...


class ZenohTransport:
    """The relay on a Zenoh router session: nodes publish on ``up/<node>``, the relay on
    ``down``; liveliness tokens say who is attached; anyone may ask ``status``."""

    direct: Mapping[str, DirectStep] = MappingProxyType({})  # every node steps in a process of its own
    serves_status = True

    def __init__(self, session: zenoh.Session) -> None:
        self.session = session
        self._declared: list[Any] = []

    def open(self, keys: ProjectKeys, polls: bool, low_latency: bool,
             status: Callable[[int | None], dict[str, Any]], answers: AnswerBudget) -> tuple[Inbox, FramePublisher]:
        """The inbox on every node's ``up`` key, the publisher on ``down``, the server's token,
        a watch on the nodes' tokens, and the status queryable."""
        session = self.session
        inbox = Inbox(session, keys.up_all, f"{keys.root}/up/_local", poll=polls)
        release = FramePublisher(session, keys.down, low_latency=low_latency)

        def on_liveliness(sample: zenoh.Sample) -> None:
            node = ProjectKeys.last_chunk(str(sample.key_expr))
            inbox.inject(frames.encode(frames.LIVE, node, sample.kind == zenoh.SampleKind.PUT))

        def on_status(query: zenoh.Query) -> None:
            if not answers.take():
                query.reply_err(f"busy: over {answers.per_s:g} status answers a second; ask again".encode())
                return
            since = query.parameters.get("since")
            try:
                after = int(since) if since is not None and len(since) < 20 else None
            except ValueError:
                after = None  # anyone may ask: a selector that is no step asks for no points
            # A byte port's value is no JSON: it goes as null (the dashboard plots numbers only).
            query.reply(keys.status, json.dumps(status(after), default=lambda _: None))

        self._declared = [
            session.liveliness().declare_token(keys.alive(SERVER_TOKEN)),
            session.liveliness().declare_subscriber(keys.alive_all, on_liveliness, history=True),
            session.declare_queryable(keys.status, on_status),
        ]
        return inbox, release

    def close(self) -> None:
        """Undeclare the queryable, the watch and the token (the session stays the caller's)."""
        for decl in reversed(self._declared):
            try:
                decl.undeclare()
            except Exception:  # the session may already be closed
                pass
        self._declared = []


class InProcessTransport:
    """The relay and its nodes in one process (:mod:`hycosim.transport.local_bus`): no session, no
    status queryable, no gateway; the nodes attached to the bus before the run, and their
    macro steps calls where the run allows (the relay's plan)."""

    session = None
    serves_status = False

    def __init__(self, bus: LocalBus) -> None:
        self.bus = bus
        self.direct = bus.direct

    def open(self, keys: ProjectKeys, polls: bool, low_latency: bool,
             status: Callable[[int | None], dict[str, Any]], answers: AnswerBudget) -> tuple[Any, Any]:
        """The bus's inbox and release publisher."""
        return self.bus.inbox, self.bus.release

    def close(self) -> None:
        """Nothing is declared in process."""
