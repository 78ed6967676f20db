"""Zenoh session setup shared by the server (a router) and the nodes (clients)."""

from __future__ import annotations

import json
import os
import re
import threading

import zenoh

# Zenoh's low-latency transport writes each message in one batch and cannot fragment: on
# loopback a 50 kB message was dropped without an error. Frames are kept well below that.
LOW_LATENCY_MAX_FRAME = 32 * 1024


# Zenoh runs its I/O on Tokio runtimes (tx, rx, acc, net, app), each with its own threads,
# and by default a received frame crosses two or three of them (the runtime that owns
# the socket, then an rx worker) before Python sees it. A hycosim process exchanges a few
# small frames per macro step, so those hand-offs are most of its cost: receiving on the
# app runtime instead gave +25-50 % macro steps/s on 2 cores (ring of gains, N = 2 to 16;
# benchmarks/barrier.py, medians of interleaved runs). tx keeps its own thread: while a
# link is cut its writer holds the thread it runs on. app keeps two workers so that one
# busy task never stalls the leases of the others.
SHARED_RUNTIME = "(rx: (handover: app), acc: (handover: app), net: (handover: app), app: (worker_threads: 2))"


def prefer_shared_runtime() -> str:
    """Ask Zenoh to receive on the app runtime (SHARED_RUNTIME) unless ``ZENOH_RUNTIME`` is set.

    Zenoh reads the variable once, when its runtime first starts: call this before the
    process opens its first session. Child processes inherit it. Returns the setting in use.
    """
    return os.environ.setdefault("ZENOH_RUNTIME", SHARED_RUNTIME)


class ConnectError(RuntimeError):
    """A Zenoh session that could not be opened, with the endpoint it was for."""


class FrameTooLarge(RuntimeError):
    """A frame over the size the low-latency transport can carry; the caller adds who sent it."""

    def __init__(self, size: int, limit: int):
        super().__init__(f"{size} bytes, over the {limit} bytes a low-latency link carries "
                         '(set "lowLatency": false in the project\'s coSimulation to send larger frames)')
        self.size, self.limit = size, limit


class FramePublisher:
    """A Zenoh publisher that refuses frames its transport would drop silently."""

    def __init__(self, session: zenoh.Session, key: str, *, low_latency: bool):
        self._pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK, express=True)
        self._limit = LOW_LATENCY_MAX_FRAME if low_latency else None

    def put(self, payload: bytes) -> None:
        """Send one frame; raise FrameTooLarge (nothing sent) if it cannot be carried."""
        if self._limit is not None and len(payload) > self._limit:
            raise FrameTooLarge(len(payload), self._limit)
        self._pub.put(payload)


# Zenoh's errors end with where in its Rust sources they were raised ("... at
# /root/.cargo/git/.../orchestrator.rs:388."): noise to a user, so it is cut.
_RUST_LOCATION = re.compile(r"\s*\bat\s+\S+\.rs:\d+\.?")


def zenoh_message(exc: BaseException) -> str:
    """The first line of a Zenoh error without its Rust source locations."""
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return _RUST_LOCATION.sub("", text).strip()


def _config(settings: dict[str, object]) -> zenoh.Config:
    conf = zenoh.Config()
    for key, value in settings.items():
        try:
            conf.insert_json5(key, json.dumps(value))
        except zenoh.ZError as exc:
            raise ConnectError(f"Zenoh refused the setting {key} = {json.dumps(value)}: {zenoh_message(exc)}") from None
    return conf


def _transport(low_latency: bool) -> dict[str, object]:
    # Low latency needs QoS off (it has a single queue). Each side only offers it: a peer
    # configured otherwise still connects, over the standard transport.
    if not low_latency:
        return {}
    return {"transport/unicast/lowlatency": True, "transport/unicast/qos/enabled": False}


def router_config(listen: str, *, lease_ms: int = 1000, security: dict | None = None,
                  low_latency: bool = True) -> zenoh.Config:
    """Config for the relay server: a Zenoh router listening on exactly one endpoint.

    Multicast scouting is off so that nothing beyond the named endpoint is reached; a
    short lease lets nodes notice a cut link within about a second. ``security`` adds
    ``transport/auth/usrpwd``, ``access_control`` and TLS blocks (see core.security).
    ``low_latency`` offers Zenoh's low-latency transport (frames up to
    LOW_LATENCY_MAX_FRAME bytes).
    """
    settings: dict[str, object] = {
        "mode": "router",
        "listen/endpoints": [listen],
        "scouting/multicast/enabled": False,
        # zenoh.open waits this long (500 ms) for peers that scouting finds before it returns.
        # The server has none to find (no multicast, no endpoint to connect to), so every run
        # started half a second later than it could, its nodes attached and waiting.
        "scouting/delay": 0,
        "transport/link/tx/lease": lease_ms,
        **_transport(low_latency),
    }
    settings.update(security or {})
    return _config(settings)


def client_config(connect: str, *, timeout_s: float = 10.0, lease_ms: int = 1000,
                  user: str | None = None, password: str | None = None, low_latency: bool = True,
                  tls: dict | None = None) -> zenoh.Config:
    """Config for a node: a Zenoh client of the relay server.

    A short link lease lets the server notice a frozen node within about a second.
    ``user``/``password`` authenticate the node to a server that requires it.
    ``low_latency`` as in :func:`router_config`. ``tls`` adds ``transport/link/tls``
    settings (see hycosim.transport.security.client_tls) for a ``tls/`` endpoint.
    """
    settings: dict[str, object] = {
        "mode": "client",
        "connect/endpoints": [connect],
        "connect/timeout_ms": int(timeout_s * 1000),
        # A node usually starts with its server (hycosim run, compose) and so before it listens.
        # Zenoh's retries (1 s, doubling to 4 s) made every run wait for one: 0.3 s a run on
        # loopback. A refused connect is cheap, so retry sooner: 50 ms, by 1.5 up to 0.5 s.
        "connect/retry": {"period_init_ms": 50, "period_max_ms": 500, "period_increase_factor": 1.5},
        "scouting/multicast/enabled": False,
        "transport/link/tx/lease": lease_ms,
        **_transport(low_latency),
    }
    if user is not None:
        settings["transport/auth/usrpwd"] = {"user": user, "password": password or ""}
    settings.update(tls or {})
    return _config(settings)


def token_held(session: zenoh.Session, key: str, timeout: float) -> bool:
    """Whether any session on the network holds the liveliness token ``key`` (asked, not watched)."""
    return any(reply.ok is not None for reply in session.liveliness().get(key, timeout=timeout))


def open_session(conf: zenoh.Config, endpoint: str) -> zenoh.Session:
    """Open a session; raise ConnectError naming the endpoint if that fails.

    ``zenoh.open`` does not return to Python until it connects or its connect timeout passes,
    so Ctrl-C would wait that long (30 s for a node whose server is not up). It runs in a
    helper thread while this one waits in short slices, where a KeyboardInterrupt is raised
    at once; a session that opens after that is closed by the helper.
    """
    outcome: list[zenoh.Session | BaseException] = []
    abandoned = threading.Event()
    handover = threading.Lock()  # the session is either handed over or closed, never neither

    def attempt() -> None:
        try:
            session = zenoh.open(conf)
        except Exception as exc:  # zenoh raises ZError with the Rust message
            outcome.append(exc)
            return
        with handover:
            if abandoned.is_set():
                session.close()
            else:
                outcome.append(session)

    helper = threading.Thread(target=attempt, name="zenoh-open", daemon=True)
    helper.start()
    try:
        while helper.is_alive():
            helper.join(0.1)
    except KeyboardInterrupt:
        with handover:
            abandoned.set()
            if outcome and isinstance(outcome[0], zenoh.Session):
                outcome[0].close()
        raise
    if outcome and isinstance(outcome[0], zenoh.Session):
        return outcome[0]
    reason = zenoh_message(outcome[0]) if outcome else "the attempt ended without an answer"
    raise ConnectError(f"cannot open Zenoh session on {endpoint}: {reason}") from None
