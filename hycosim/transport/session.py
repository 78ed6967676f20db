"""Zenoh session setup shared by the server (a router) and the nodes (clients)."""

from __future__ import annotations

import fcntl
import ipaddress
import json
import os
import re
import socket
import stat
import sys
import threading
import time
from pathlib import Path

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
        #: The largest frame the transport carries (``sys.maxsize``: any).
        self.limit = LOW_LATENCY_MAX_FRAME if low_latency else sys.maxsize
        #: Zenoh's put, unchecked: for a loop that sends a frame at every step and compares its
        #: length with :attr:`limit` itself (one call less a frame; a node's flat path).
        self.unchecked_put = self._pub.put

    def put(self, payload: bytes) -> None:
        """Send one frame; raise FrameTooLarge (nothing sent) if it cannot be carried."""
        if len(payload) > self.limit:
            raise FrameTooLarge(len(payload), self.limit)
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


# A node on its server's host may reach it over a Unix socket instead of TCP on loopback:
# 2-5 % less CPU a macro step and 7-11 % more macro steps/s with 4 and 8 nodes blocking on 2
# cores (benchmarks/FINDINGS.md, 2026-12-04, eighth entry). The folder is the same for every process
# of the host whatever its TMPDIR (HYCOSIM_SOCKETS, where set for all of them, moves it); the
# socket's name says which network namespace's loopback and which port it stands beside, since
# servers in other namespaces may use the same port.
LOCAL_SOCKETS = "/tmp"


def local_socket(endpoint: str) -> Path | None:
    """The Unix socket a server listening on ``endpoint`` also listens on, where that is TCP
    on a loopback address (reached from this host alone); None for any other endpoint."""
    kind, _, address = endpoint.partition("/")
    host, colon, port = address.rpartition(":")
    if kind != "tcp" or not colon or not (port.isascii() and port.isdigit()):
        return None
    host = host.strip("[]")
    if host != "localhost":
        try:
            if not ipaddress.ip_address(host).is_loopback:
                return None
        except ValueError:  # a host name: it may be this host or any other
            return None
    try:
        netns = os.stat("/proc/self/ns/net").st_ino
    except OSError:
        return None
    folder = Path(os.environ.get("HYCOSIM_SOCKETS", LOCAL_SOCKETS))
    if not folder.is_absolute():  # the server and its nodes may not share a working folder
        return None
    path = folder / f"hycosim-{os.getuid()}" / f"{netns}-{port}.sock"
    # A socket's path has room for 107 bytes: a longer one could not be listened on.
    return path if len(os.fsencode(path)) <= 107 else None


def server_socket(endpoint: str) -> tuple[Path | None, str | None]:
    """The Unix socket a server on ``endpoint`` listens on beside it (:func:`local_socket`),
    its folder swept of what killed servers left (:func:`sweep_sockets`); (None, why) where
    its folder is not its user's alone, (None, None) where ``endpoint`` takes no socket."""
    local = local_socket(endpoint)
    if local is None:
        return None, None
    if not private_folder(local.parent):
        return None, f"its folder {local.parent} is not this user's alone"
    sweep_sockets(local.parent)
    return local, None


def private_folder(folder: Path) -> bool:
    """Whether ``folder`` is (made, where missing) a folder of this user's alone: a server
    listens on a socket there only then, so that nobody else can stand in for it."""
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        info = folder.lstat()
    except OSError:
        return False
    return stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid() and info.st_mode & 0o077 == 0


def sweep_sockets(folder: Path) -> int:
    """Remove the sockets in ``folder`` that no server listens on any more (one killed leaves
    its socket and lock file behind); return how many. A listening router holds its socket's
    lock file (flock) while it listens: a lock that can be taken has no owner left."""
    swept = 0
    for lock in folder.glob("*.sock.lock"):
        try:
            fd = os.open(lock, os.O_RDWR | os.O_NOFOLLOW)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # held: its server is listening
            os.close(fd)
            continue
        try:
            Path(str(lock)[:-len(".lock")]).unlink(missing_ok=True)
            lock.unlink(missing_ok=True)
            swept += 1
        except OSError:
            pass
        finally:
            os.close(fd)
    return swept


def _accepts(family: int, address: object) -> bool:
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.settimeout(0.5)
        try:
            probe.connect(address)
        except OSError:
            return False
    return True


def reach(endpoint: str, timeout_s: float) -> str:
    """The endpoint a node connects to its server at ``endpoint`` by: the server's Unix socket
    beside it (:func:`local_socket`) once it listens there, else ``endpoint`` (one that takes
    no socket, the server up on TCP alone, or not up within ``timeout_s``, which Zenoh's
    connect then reports).

    A node usually starts before its server listens. Zenoh's client cannot choose itself: an
    endpoint it cannot reach holds it until its connect timeout though the next one listens.
    A probe is a connection opened and closed, which the router drops as a link that never
    said hello."""
    local = local_socket(endpoint)
    if local is None:
        return endpoint
    host, _, port = endpoint.partition("/")[2].rpartition(":")
    unix = f"unixsock-stream/{local}"
    deadline, pause = time.monotonic() + timeout_s, 0.05
    while True:
        if _accepts(socket.AF_UNIX, str(local)):
            return unix
        if _accepts(socket.AF_INET6 if ":" in host else socket.AF_INET, (host.strip("[]"), int(port))):
            # The server opens both in one call: its socket follows its TCP port within moments.
            until = time.monotonic() + 0.2
            while time.monotonic() < until:
                if _accepts(socket.AF_UNIX, str(local)):
                    return unix
                time.sleep(0.01)
            return endpoint
        if time.monotonic() + pause >= deadline:
            return endpoint
        time.sleep(pause)
        pause = min(1.5 * pause, 0.5)


def router_config(listen: str, *, lease_ms: int = 1000, security: dict | None = None,
                  low_latency: bool = True, local: Path | None = None) -> zenoh.Config:
    """Config for the relay server: a Zenoh router listening on exactly one endpoint (and on
    the Unix socket ``local`` beside it, where given: :func:`local_socket`).

    Multicast scouting is off so that nothing beyond the named endpoint is reached; a
    short lease lets nodes notice a cut link within about a second. ``security`` adds
    ``transport/auth/usrpwd``, ``access_control`` and TLS blocks (see core.security).
    ``low_latency`` offers Zenoh's low-latency transport (frames up to
    LOW_LATENCY_MAX_FRAME bytes).
    """
    settings: dict[str, object] = {
        "mode": "router",
        "listen/endpoints": [listen] if local is None else [listen, f"unixsock-stream/{local}"],
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
