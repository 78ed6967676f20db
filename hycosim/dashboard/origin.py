"""Who may read the dashboard: requests addressed to it, and feeds opened by its own page.

A dashboard on 127.0.0.1 is within reach of every web page the user's browser shows, and
the browser lets two attacks through that would read the run (its ports, values, hosts and
guard values; for a secured project, what its monitor's credentials let it see):

- *Cross-site WebSocket hijacking*: a page from another site opens ``ws://127.0.0.1:8050/ws``.
  The browser sends the page's ``Origin`` but enforces nothing, so a feed whose Origin is
  not the dashboard's own is refused (403), unless the user allowed that origin (a page that
  embeds the dashboard, a reverse proxy of another name).
- *DNS rebinding*: a name the attacker controls is made to resolve to 127.0.0.1, after which
  the attacker's page is same-origin with the dashboard and reads ``/api/snapshot``. A
  dashboard that listens on a loopback address answers only requests whose ``Host`` is a
  loopback name or address (whatever the port: an ssh tunnel may forward another).

Programs that are no browser (the benchmark's client, curl) send no Origin and are let
through: they are no page of another site. Jupyter and Bokeh guard their servers alike.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Awaitable, Callable, Iterable, MutableMapping
from typing import Any
from urllib.parse import urlsplit

Scope = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[MutableMapping[str, Any]]]
Send = Callable[[MutableMapping[str, Any]], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]


def split_host(text: str) -> tuple[str, int | None] | None:
    """A ``Host`` header's name (lower case, IPv6 without brackets) and port; None if malformed."""
    text = text.strip().lower()
    if text.startswith("["):
        name, bracket, rest = text[1:].partition("]")
        if not bracket or (rest and not rest.startswith(":")):
            return None
        port_text = rest[1:] if rest else None
    else:
        name, colon, port_text = text.partition(":")
        port_text = port_text if colon else None
    if not name or (port_text is not None and not (port_text.isascii() and port_text.isdigit()
                                                    and 0 < int(port_text) < 65536)):
        return None
    return name, None if port_text is None else int(port_text)


def is_loopback(name: str) -> bool:
    """Whether a host name or address stays on this machine (``localhost``, ``*.localhost``,
    127.0.0.0/8, ``::1``)."""
    if name == "localhost" or name.endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def normal_origin(text: str) -> str | None:
    """An origin as ``scheme://host:port`` (the scheme's port filled in); None if it is none
    (``null``, a path, another scheme)."""
    try:
        parts = urlsplit(text.strip().lower())
        port = parts.port or {"http": 80, "https": 443}.get(parts.scheme)
    except ValueError:
        return None
    if parts.scheme not in ("http", "https") or not parts.hostname or parts.path not in ("", "/"):
        return None
    host = f"[{parts.hostname}]" if ":" in parts.hostname else parts.hostname
    return f"{parts.scheme}://{host}:{port}"


def refusal(kind: str, host: str | None, origin: str | None, *, loopback_only: bool,
            allowed: frozenset[str] = frozenset()) -> str | None:
    """Why a request (``kind``: ``http`` or ``websocket``) with these ``Host`` and ``Origin``
    headers is refused, or None when it is answered. ``allowed``: origins (as
    :func:`normal_origin` writes them) whose pages may open the feed besides the dashboard's own."""
    where = split_host(host) if host is not None else None
    if host is not None and where is None:
        return "a malformed Host header"
    named = {urlsplit(o).hostname for o in allowed}  # a proxy of that name may pass its own Host on
    if loopback_only and (where is None or not (is_loopback(where[0]) or where[0] in named)):
        return (f"Host {host!r} is not this machine: the dashboard listens on a loopback address "
                "and answers requests addressed to it alone")
    if kind != "websocket" or origin is None:
        return None
    theirs = normal_origin(origin)
    if theirs is not None and theirs in allowed:
        return None
    if theirs is None or where is None:
        return f"a feed opened by a page of origin {origin[:80]!r}, not the dashboard's own"
    name, port = urlsplit(theirs).hostname, urlsplit(theirs).port
    if name != where[0] or (where[1] is not None and port != where[1]) or (where[1] is None and port not in (80, 443)):
        return (f"a feed opened by a page of origin {origin[:80]!r}, not the dashboard's own; "
                "allow it with --allow-origin")
    return None


class OwnOriginOnly:
    """ASGI middleware answering a refused request (:func:`refusal`) with 403 and its reason."""

    def __init__(self, app: ASGIApp, *, loopback_only: bool, allowed: Iterable[str] = ()):
        self.app = app
        self.loopback_only = loopback_only
        self.allowed = frozenset(o for o in (normal_origin(a) for a in allowed) if o is not None)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers: dict[str, str] = {}
        for key, value in scope.get("headers", ()):
            headers.setdefault(key.decode("latin-1").lower(), value.decode("latin-1"))
        why = refusal(scope["type"], headers.get("host"), headers.get("origin"),
                      loopback_only=self.loopback_only, allowed=self.allowed)
        if why is None:
            await self.app(scope, receive, send)
        elif scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 1008, "reason": why[:120]})  # before accept: 403
        else:
            body = f"refused: {why}\n".encode()
            await send({"type": "http.response.start", "status": 403,
                        "headers": [(b"content-type", b"text/plain; charset=utf-8"),
                                    (b"content-length", str(len(body)).encode())]})
            await send({"type": "http.response.body", "body": body})
