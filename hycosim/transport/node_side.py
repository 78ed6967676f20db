"""A node's end of a transport: how its frames go up to the master and come down from it.

The node runtime handles every frame the master releases in one place
(:meth:`hycosim.node.runtime.NodeRuntime.handle`) whatever carries it; a :class:`NodeLink`
is what differs. Over Zenoh (:class:`ZenohNodeLink`) the runtime pulls the frames from the
link's inbox and feeds them to its handler; in process (:class:`LocalNodeLink`) the master
pushes them, calling the handler in its own thread, and there is nothing to pull.
"""

from __future__ import annotations

import json
import os
import time
from typing import Protocol

import zenoh

from hycosim.core import frames
from hycosim.core.config import LoadedProject
from hycosim.transport.inbox import Inbox
from hycosim.transport.keys import SERVER_TOKEN, ProjectKeys
from hycosim.transport.local_bus import LocalBus
from hycosim.transport.security import client_tls
from hycosim.transport.session import ConnectError, FramePublisher, client_config, open_session, reach, token_held


class NodeLink(Protocol):
    """One node's end of a transport."""

    def send(self, payload: bytes) -> None:
        """Send one frame to the master (FrameTooLarge where the link cannot carry it)."""

    def receive(self, timeout: float) -> tuple[str, bytes] | None:
        """The next frame for this node within ``timeout`` seconds, as (key, payload); None when
        none came, or at once where the master pushes its frames instead."""

    @property
    def waits(self) -> dict[str, int] | None:
        """How the receiving waited (for the node's last log line), where it counts that."""

    def close(self) -> None:
        """Leave: this end takes and sends nothing more."""


class ZenohNodeLink(NodeLink):
    """A node's Zenoh client session: a publisher on its ``up`` key, an inbox on the server's
    ``down`` key, its liveliness token, and a watch on the server's token whose news comes
    through the inbox as LIVE frames. Opened by :meth:`open`; closed once, in a ``finally``."""

    def __init__(self, session: zenoh.Session, loaded: LoadedProject, name: str, endpoint: str):
        self.session, self.endpoint = session, endpoint
        self.over = endpoint  # the endpoint connected to: ``endpoint``, or the server's Unix socket beside it
        self._project = loaded.project.projectName
        self._keys = ProjectKeys(self._project)
        self._inbox: Inbox | None = None
        self._undeclare: list = []
        try:
            # Before any declaration: a refused node leaves nothing behind to fire as it closes.
            if token_held(session, self._keys.alive(name), timeout=min(5.0, loaded.project.coSimulation.attachTimeout)):
                raise ConnectError(f"node {name!r} is already attached to the server at {endpoint}: "
                                   "another process holds its liveliness token (one process per node)")
            cosim = loaded.project.coSimulation
            self._inbox = Inbox(session, self._keys.down, self._keys.down,
                                poll=loaded.project.polls_before_blocking(os.cpu_count()))
            self.receive = self._inbox.recv  # receive(), as the call it makes, until close()
            self.publisher = FramePublisher(session, self._keys.up(name), low_latency=cosim.lowLatency)
            self.send = self.publisher.put  # send(), as the call it makes: one call less at every step
            # history: fetch the server's token now. Without it this session learnt of the token
            # only if the router's announcement won a race with the subscription (it lost about one
            # attach in fifteen with Zenoh receiving on the app runtime), and a session that never
            # knew the token never reports it gone, so a cut link went unnoticed.
            watch = session.liveliness().declare_subscriber(self._keys.alive(SERVER_TOKEN), self._on_server,
                                                            history=True)
            self._undeclare.append(watch.undeclare)
            # Declared after the subscriber: the server starts once it sees this token.
            token = session.liveliness().declare_token(self._keys.alive(name))
            self._undeclare.insert(0, token.undeclare)
        except BaseException:
            self.close()
            raise

    @classmethod
    def open(cls, loaded: LoadedProject, name: str, endpoint: str, password: str | None = None) -> ZenohNodeLink:
        """Connect to the server at ``endpoint`` as node ``name`` (authenticated as the user of
        that name where ``password`` is given) and declare what the node needs."""
        cosim = loaded.project.coSimulation
        polls = loaded.project.polls_before_blocking(os.cpu_count())
        started = time.monotonic()
        connect = reach(endpoint, cosim.attachTimeout) if cosim.localSocket and not polls else endpoint
        # What the probe took comes off Zenoh's connect timeout: the attach timeout bounds both.
        timeout = max(cosim.attachTimeout - (time.monotonic() - started), 1.0)
        conf = client_config(connect, timeout_s=timeout, low_latency=cosim.lowLatency,
                             user=name if password is not None else None, password=password,
                             tls=client_tls(loaded, endpoint))
        try:
            session = open_session(conf, endpoint)
        except ConnectError as exc:
            if password is not None:
                raise ConnectError(f"{exc} (node {name!r} authenticates as user {name!r}: "
                                   "wrong credentials are refused this way too)") from None
            raise
        try:
            link = cls(session, loaded, name, endpoint)
        except BaseException:
            session.close()
            raise
        link.over = connect
        return link

    def _on_server(self, sample: zenoh.Sample) -> None:
        if self._inbox is not None:
            self._inbox.inject(frames.encode(frames.LIVE, SERVER_TOKEN, sample.kind == zenoh.SampleKind.PUT))

    def send(self, payload: bytes) -> None:
        self.publisher.put(payload)

    def receive(self, timeout: float) -> tuple[str, bytes] | None:
        return self._inbox.recv(timeout) if self._inbox is not None else None

    @property
    def waits(self) -> dict[str, int] | None:
        return self._inbox.waits if self._inbox is not None else None

    def other_projects(self) -> str:
        """A hint for a node that heard nothing from its server: the endpoint may serve another project."""
        found = []
        try:
            for reply in self.session.get(ProjectKeys("*").status, timeout=2.0):
                if reply.ok is not None:
                    found.append(str(json.loads(reply.ok.payload.to_bytes()).get("project")))
        except Exception:  # a hint only: a refused query (access control) or a bad answer gives none
            return ""
        if not found or self._project in found:
            return ""
        return (f"; the server there runs project {', '.join(map(repr, sorted(found)))}, not "
                f"{self._project!r}: is this the project file the server was started with?")

    def close(self) -> None:
        for undeclare in self._undeclare:
            undeclare()
        self._undeclare = []
        if self._inbox is not None:
            del self.receive  # the class's receive() again: None from here on
            self._inbox.close()
            self._inbox = None


class LocalNodeLink(NodeLink):
    """A node's end of an in-process run: its frames go into the master's inbox, and the master
    hands it each release by calling the runtime, so nothing is ever received here."""

    def __init__(self, bus: LocalBus, name: str):
        self._bus, self._name = bus, name
        self._put = bus.publisher(name).put

    def send(self, payload: bytes) -> None:
        self._put(payload)

    def receive(self, timeout: float) -> tuple[str, bytes] | None:
        return None

    @property
    def waits(self) -> dict[str, int] | None:
        return None

    def close(self) -> None:
        self._bus.leave(self._name)
