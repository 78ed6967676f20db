"""Credentials, access control and TLS for remote attach.

The server is a Zenoh router with ``transport/auth/usrpwd``: a client without the right
user and password never gets a session. With ``acl`` on, the router's access control lets
each node (user = node name) publish only on its own ``up/<node>`` key and declare only
its own liveliness token, so an authenticated node cannot inject values for another; the
server's UID check stays as a second line. With ``tls`` the server listens on a
``tls/HOST:PORT`` endpoint: the link is encrypted and a node attaches only to a server
whose certificate the project's CA signed. TLS settings apply to ``tls/`` endpoints only,
so an embedded run on TCP loopback needs none of the files.
"""

from __future__ import annotations

import os
from pathlib import Path

from hycosim.core.config import LoadedProject
from hycosim.transport.keys import SERVER_TOKEN, ProjectKeys

SERVER_USER = "server"
PASSWORD_ENV = "HYCOSIM_PASSWORD"


class SecurityError(RuntimeError):
    """Credentials that cannot be read or are incomplete; names the file or user."""


def _read_text(path: Path, what: str) -> str:
    try:
        return path.read_bytes().decode()
    except OSError as exc:
        raise SecurityError(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise SecurityError(f"{path}: cannot read {what} (not UTF-8 text at byte {exc.start})") from None


# What Zenoh's dictionary reader trims around a line, a user and a password: Rust's
# char::is_whitespace (Unicode White_Space). Python's str.strip also drops \x1c-\x1f,
# which Zenoh keeps, so a password ending in one would not match.
_ZENOH_SPACE = ("\t\n\x0b\x0c\r \x85\xa0\u1680" + "".join(map(chr, range(0x2000, 0x200B)))
                + "\u2028\u2029\u202f\u205f\u3000")


def read_password(path: Path) -> str:
    """The password in a file: its one line, the spaces around it dropped as Zenoh drops them
    in a dictionary file; SecurityError naming the file if it is unreadable, empty or has more."""
    password = _read_text(path, "the password").strip(_ZENOH_SPACE)
    if not password:
        raise SecurityError(f"{path}: holds no password")
    if "\n" in password or "\r" in password:
        raise SecurityError(f"{path}: holds more than one line; a password is one line")
    return password


def read_credentials(path: Path) -> dict[str, str]:
    """The users and passwords of a Zenoh dictionary file, read as Zenoh 1.x reads it: lines
    split at ``\n`` (a ``\r`` before it dropped), blank lines skipped, ``user:password`` split
    at the first colon, each side trimmed, neither empty. SecurityError naming the file and
    line where Zenoh would refuse the file, or read it otherwise than its author meant:
    Zenoh has no comments (``# a:b`` would be a user ``# a``) and keeps a byte-order mark
    as part of the first user's name."""
    text = _read_text(path, "credentials")
    if text.startswith("\ufeff"):
        raise SecurityError(f"{path}: starts with a byte-order mark, which Zenoh reads as part of the first "
                            "user's name; save it as UTF-8 without one")
    users = {}
    for n, raw in enumerate(text.split("\n"), 1):
        line = raw.removesuffix("\r").strip(_ZENOH_SPACE)
        if not line:
            continue
        if line.startswith("#"):
            raise SecurityError(f"{path}:{n}: a Zenoh dictionary file has no comments; remove the line")
        user, sep, password = line.partition(":")
        user, password = user.strip(_ZENOH_SPACE), password.strip(_ZENOH_SPACE)
        if not sep:
            raise SecurityError(f"{path}:{n}: expected 'user:password'")
        if not user:
            raise SecurityError(f"{path}:{n}: no user before the colon")
        if not password:
            raise SecurityError(f"{path}:{n}: user {user!r} has no password")
        users[user] = password
    return users


def credentials_path(loaded: LoadedProject) -> Path | None:
    """The project's credentials file, resolved; None when it has none."""
    sec = loaded.project.security
    return loaded.resolve(sec.credentials) if sec and sec.credentials else None


def _pem(path: Path, what: str) -> str:
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError as exc:
        raise SecurityError(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    if b"-----BEGIN " not in head:
        raise SecurityError(f"{path}: the {what} is not a PEM file")
    return str(path)


def router_tls(loaded: LoadedProject, endpoint: str) -> dict:
    """The router's ``transport/link/tls`` settings for a ``tls/`` endpoint, or {}."""
    sec = loaded.project.security
    if not endpoint.startswith("tls/") or sec is None or sec.tls is None:
        return {}
    tls = sec.tls
    if tls.certificate is None or tls.privateKey is None:
        raise SecurityError(f"{loaded.path}: the server needs security.tls.certificate and privateKey "
                            f"to listen on {endpoint}")
    return {"transport/link/tls/listen_certificate": _pem(loaded.resolve(tls.certificate), "server certificate"),
            "transport/link/tls/listen_private_key": _pem(loaded.resolve(tls.privateKey), "server private key")}


def client_tls(loaded: LoadedProject, endpoint: str) -> dict:
    """A node's ``transport/link/tls`` settings (the CA it checks the server against), or {}."""
    sec = loaded.project.security
    if not endpoint.startswith("tls/"):
        return {}
    if sec is None or sec.tls is None:
        raise SecurityError(f"{endpoint} is a TLS endpoint but {loaded.path} has no security.tls.rootCa "
                            "to check the server's certificate against")
    return ca_settings(loaded.resolve(sec.tls.rootCa))


def ca_settings(ca: Path) -> dict:
    """``transport/link/tls`` settings for a client that checks the server against ``ca`` (PEM)."""
    return {"transport/link/tls/root_ca_certificate": _pem(ca.resolve(), "root CA certificate")}


def router_security(loaded: LoadedProject, endpoint: str = "") -> dict:
    """The router's ``transport/auth/usrpwd``, ``access_control`` and TLS settings, or {}."""
    path = credentials_path(loaded)
    if path is None:
        return router_tls(loaded, endpoint)
    users = read_credentials(path)
    if SERVER_USER not in users:
        raise SecurityError(f"{path}: no '{SERVER_USER}' user (the relay server's own credentials)")
    settings: dict = {"transport/auth/usrpwd": {"user": SERVER_USER, "password": users[SERVER_USER],
                                                "dictionary_file": str(path)}, **router_tls(loaded, endpoint)}
    if not loaded.project.security.acl:
        return settings
    settings["access_control"] = access_rules(ProjectKeys(loaded.name), [n.nodeName for n in loaded.project.nodeLists],
                                              sorted(set(users) - {n.nodeName for n in loaded.project.nodeLists}
                                                     - {SERVER_USER}))
    return settings


def _rule(rule_id: str, messages: list[str], key_exprs: list[str], flow: str = "ingress") -> dict:
    return {"id": rule_id, "flows": [flow], "permission": "allow", "messages": messages, "key_exprs": key_exprs}


def access_rules(keys: ProjectKeys, nodes: list[str], monitors: list[str]) -> dict:
    """The router's ``access_control`` block: each permission granted on exactly its keys.

    A node may put only on its own ``up/<node>``, declare only its own liveliness token,
    subscribe to ``down``, watch and ask after the server's token (and ask after its own,
    to refuse a second process), and query ``status``. Monitors (users that are no node) may
    subscribe, watch liveliness and query. Nobody but the server, the router itself (whose
    own session is not subject to these rules), may put on ``down``, declare a queryable or
    delete; anything not allowed is denied. Egress is open: what a client may subscribe to
    is decided on its way in.
    """
    rules = [_rule("to-all", ["put", "delete", "declare_subscriber", "liveliness_token",
                              "declare_liveliness_subscriber", "reply", "declare_queryable"],
                   [f"{keys.root}/**"], flow="egress"),
             _rule("subscribe-down", ["declare_subscriber"], [keys.down]),
             _rule("watch-server", ["declare_liveliness_subscriber", "liveliness_query"], [keys.alive(SERVER_TOKEN)]),
             _rule("ask-status", ["query"], [keys.status])]
    subjects, policies = [], []
    common = ["to-all", "subscribe-down", "watch-server", "ask-status"]
    for node in nodes:
        rules.append(_rule(f"put-{node}", ["put"], [keys.up(node)]))
        rules.append(_rule(f"token-{node}", ["liveliness_token", "liveliness_query"], [keys.alive(node)]))
        subjects.append({"id": node, "usernames": [node]})
        policies.append({"id": f"node-{node}", "rules": [*common, f"put-{node}", f"token-{node}"], "subjects": [node]})
    if monitors:
        rules.append(_rule("monitor", ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
                           [f"{keys.root}/**"]))
        subjects.append({"id": "monitors", "usernames": monitors})
        policies.append({"id": "monitors", "rules": ["to-all", "ask-status", "monitor"], "subjects": ["monitors"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def node_password(loaded: LoadedProject, node: str, password_file: Path | None) -> str | None:
    """A node's password: --password-file, else $HYCOSIM_PASSWORD, else the project's
    credentials file when it is at hand (local runs); None when the project needs none."""
    if credentials_path(loaded) is None:
        return None
    if password_file is not None:
        return read_password(password_file)
    if os.environ.get(PASSWORD_ENV):
        return os.environ[PASSWORD_ENV]
    path = credentials_path(loaded)
    if path is not None and path.exists():
        users = read_credentials(path)
        if node in users:
            return users[node]
    raise SecurityError(f"node {node!r}: the project requires credentials; give --password-file or ${PASSWORD_ENV}")
