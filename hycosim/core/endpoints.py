"""Where the server listens and nodes connect: Zenoh endpoints and HOST:PORT addresses.

Every address a user writes (``serverIP``, ``gatewayIP``, ``--listen``, ``--connect``,
``--gateway``, the endpoint of ``hycosim status``) is read here before any session is
opened, so a typo gets a message that says what is wrong with it instead of Zenoh's parse
error (or a Python traceback when a port is not a number).

Forms accepted: ``HOST``, ``HOST:PORT``, ``[IPv6]:PORT`` and the Zenoh endpoints
``tcp/HOST:PORT`` and ``tls/HOST:PORT``, optionally followed by Zenoh's ``?metadata`` or
``#config``. hycosim speaks TCP and TLS only: the bridge FMUs' gateway sits on the server's
port + 1 of the same host, which other Zenoh link kinds (unixsock, udp) do not give.
"""

from __future__ import annotations

import re
import socket
from dataclasses import dataclass

SERVER_PORT = 7447
GATEWAY_PORT = 7448
PROTOCOLS = ("tcp", "tls")
FORMS = "HOST, HOST:PORT, tcp/HOST:PORT or tls/HOST:PORT"

# Host names (RFC 1123 labels, with _ as Docker allows), IPv4 and, in brackets, IPv6.
# Matched whole (fullmatch): "$" would let a trailing newline through.
_HOST = re.compile(r"[A-Za-z0-9_]([A-Za-z0-9_\-]*[A-Za-z0-9_])?(\.[A-Za-z0-9_]([A-Za-z0-9_\-]*[A-Za-z0-9_])?)*\.?")
_IPV6 = re.compile(r"[0-9A-Fa-f:.]+(%[A-Za-z0-9_.\-]+)?")
_DIGITS = re.compile(r"[0-9]+")  # ASCII: str.isdigit() holds for "²", which int() refuses


class EndpointError(ValueError):
    """An address hycosim cannot use; the message names it and says what is wrong."""


@dataclass(frozen=True)
class Address:
    """A host and a TCP port."""

    host: str
    port: int

    def __str__(self) -> str:
        return f"[{self.host}]:{self.port}" if ":" in self.host else f"{self.host}:{self.port}"


@dataclass(frozen=True)
class Endpoint:
    """A Zenoh endpoint hycosim can use: ``protocol/host:port`` plus Zenoh's optional suffix."""

    protocol: str
    address: Address
    suffix: str = ""  # "?metadata" and/or "#config", passed to Zenoh as written

    def __str__(self) -> str:
        return f"{self.protocol}/{self.address}{self.suffix}"


def parse_address(text: str, default_port: int) -> Address:
    """Read ``HOST``, ``HOST:PORT`` or ``[IPv6]:PORT`` (a leading ``tcp/`` is allowed); raise EndpointError."""
    rest = text.strip()
    if "/" in rest:
        protocol, rest = rest.split("/", 1)
        if protocol != "tcp":  # the gateway is plain TCP
            raise EndpointError(f"{text!r} is not a HOST:PORT address; write HOST, HOST:PORT or [IPv6]:PORT")
    return _address(rest, default_port, text)


def parse_endpoint(text: str, default_port: int = SERVER_PORT) -> Endpoint:
    """Read an endpoint in any of the forms above; a bare host or HOST:PORT becomes ``tcp/``."""
    protocol, rest = "tcp", text.strip()
    if "/" in rest:
        protocol, rest = rest.split("/", 1)
        if protocol not in PROTOCOLS:
            raise EndpointError(f"{text!r} is not an endpoint hycosim can use" + _protocol_hint(protocol))
    cut = min((i for i in (rest.find("?"), rest.find("#")) if i >= 0), default=len(rest))
    return Endpoint(protocol, _address(rest[:cut], default_port, text), rest[cut:])


def _address(rest: str, default_port: int, text: str) -> Address:
    # ``text`` is what the user wrote, for the messages.
    if not rest:
        raise EndpointError(f"{text!r} names no host; write {FORMS}")
    if rest.startswith("["):
        host, sep, after = rest[1:].partition("]")
        if not sep or (after and not after.startswith(":")):
            raise EndpointError(f"{text!r}: an IPv6 address is written [ADDRESS]:PORT")
        port_text = after[1:] if after else None
        if not _IPV6.fullmatch(host):
            raise EndpointError(f"{text!r}: {host!r} is not an IPv6 address")
    elif rest.count(":") > 1:  # a bare IPv6 address: no room for a port
        host, port_text = rest, None
        if not _IPV6.fullmatch(host):
            raise EndpointError(f"{text!r} is not an address; write {FORMS} ([IPv6]:PORT for IPv6)")
    else:
        host, sep, port_text = rest.partition(":")
        port_text = port_text if sep else None
        if len(host) > 253 or not _HOST.fullmatch(host):
            raise EndpointError(f"{text!r}: {host!r} is not a host name or IP address; write {FORMS}")
    return Address(host, _port(text, port_text, default_port))


def listen_family(host: str) -> socket.AddressFamily:
    """The socket family to listen on ``host`` with: IPv6 for an IPv6 address (which Address
    keeps without its brackets), IPv4 for anything else (a name resolves to IPv4 here)."""
    return socket.AF_INET6 if ":" in host else socket.AF_INET


def gateway_beside(server: Endpoint) -> Address:
    """The bridge FMUs' gateway by default: the server's host, the server's port + 1."""
    if server.address.port >= 65535:
        raise EndpointError(f"{server}: the gateway goes on the server's port + 1, and {server.address.port} "
                            "is the last port; choose a lower server port or give gatewayIP")
    return Address(server.address.host, server.address.port + 1)


def _port(text: str, port_text: str | None, default_port: int) -> int:
    if port_text is None:
        return default_port
    if not _DIGITS.fullmatch(port_text):
        raise EndpointError(f"{text!r}: port {port_text!r} is not a number")
    # int() refuses more than 4,300 digits; no port has more than 5 (leading zeros aside).
    port = int(port_text) if len(port_text) <= 12 else 0
    if not 1 <= port <= 65535:
        shown = port_text if len(port_text) <= 12 else port_text[:12] + "…"
        raise EndpointError(f"{text!r}: port {shown} is outside 1-65535")
    return port


def _protocol_hint(protocol: str) -> str:
    if not protocol:
        return f" (a path?); write {FORMS}"
    return f": hycosim speaks {' and '.join(p + '/' for p in PROTOCOLS)} only, not {protocol}/; write {FORMS}"
