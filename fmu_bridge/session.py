"""Zenoh session setup shared by the server (a router) and the nodes (clients)."""

from __future__ import annotations

import json

import zenoh


class ConnectError(RuntimeError):
    """A Zenoh session that could not be opened, with the endpoint it was for."""


def _config(settings: dict[str, object]) -> zenoh.Config:
    conf = zenoh.Config()
    for key, value in settings.items():
        conf.insert_json5(key, json.dumps(value))
    return conf


def router_config(listen: str, *, lease_ms: int = 1000, security: dict | None = None) -> zenoh.Config:
    """Config for the relay server: a Zenoh router listening on exactly one endpoint.

    Multicast scouting is off so that nothing beyond the named endpoint is reached; a
    short lease lets nodes notice a cut link within about a second. ``security`` adds
    ``transport/auth/usrpwd`` and ``access_control`` blocks (see fmu_bridge.security).
    """
    settings: dict[str, object] = {
        "mode": "router",
        "listen/endpoints": [listen],
        "scouting/multicast/enabled": False,
        "transport/link/tx/lease": lease_ms,
    }
    settings.update(security or {})
    return _config(settings)


def client_config(connect: str, *, timeout_s: float = 10.0, lease_ms: int = 1000,
                  user: str | None = None, password: str | None = None) -> zenoh.Config:
    """Config for a node: a Zenoh client of the relay server.

    A short link lease lets the server notice a frozen node within about a second.
    ``user``/``password`` authenticate the node to a server that requires it.
    """
    settings: dict[str, object] = {
        "mode": "client",
        "connect/endpoints": [connect],
        "connect/timeout_ms": int(timeout_s * 1000),
        "scouting/multicast/enabled": False,
        "transport/link/tx/lease": lease_ms,
    }
    if user is not None:
        settings["transport/auth/usrpwd"] = {"user": user, "password": password or ""}
    return _config(settings)


def open_session(conf: zenoh.Config, endpoint: str) -> zenoh.Session:
    """Open a session; raise ConnectError naming the endpoint if that fails."""
    try:
        return zenoh.open(conf)
    except Exception as exc:  # zenoh raises ZError with the Rust message
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConnectError(f"cannot open Zenoh session on {endpoint}: {first}") from None
