"""Test hosts in network namespaces joined by veth pairs (root only; loopback stays inside)."""

from __future__ import annotations

import os
import subprocess
from contextlib import contextmanager
from dataclasses import dataclass, field


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


def netns_available() -> bool:
    if os.geteuid() != 0:
        return False
    name = f"hyprobe{os.getpid()}"
    try:
        _ip("netns", "add", name)
        _ip("netns", "del", name)
        return True
    except (OSError, subprocess.CalledProcessError):
        return False


@dataclass
class Hosts:
    """A server namespace and client namespaces, each joined to the server by its own veth pair."""

    server: str
    clients: dict[str, str] = field(default_factory=dict)        # client → namespace
    server_address: dict[str, str] = field(default_factory=dict)  # client → server's address on its link
    links: dict[str, str] = field(default_factory=dict)           # client → its veth name (in its namespace)

    def exec(self, ns: str) -> list[str]:
        return ["ip", "netns", "exec", ns]

    def cut(self, client: str) -> None:
        _ip("-n", self.clients[client], "link", "set", self.links[client], "down")

    def restore(self, client: str) -> None:
        _ip("-n", self.clients[client], "link", "set", self.links[client], "up")


@contextmanager
def hosts(clients: list[str], subnet: int = 213):
    tag = f"{os.getpid() % 10000}"
    server = f"hys{tag}"
    made = [server]
    h = Hosts(server)
    try:
        _ip("netns", "add", server)
        _ip("-n", server, "link", "set", "lo", "up")
        for i, client in enumerate(clients, 1):
            ns = f"hy{tag}c{i}"
            _ip("netns", "add", ns)
            made.append(ns)
            _ip("-n", ns, "link", "set", "lo", "up")
            s_if, c_if = f"hs{tag}c{i}", f"hc{tag}c{i}"
            _ip("link", "add", s_if, "type", "veth", "peer", "name", c_if)
            _ip("link", "set", s_if, "netns", server)
            _ip("link", "set", c_if, "netns", ns)
            _ip("-n", server, "addr", "add", f"10.{subnet}.{i}.1/24", "dev", s_if)
            _ip("-n", ns, "addr", "add", f"10.{subnet}.{i}.2/24", "dev", c_if)
            _ip("-n", server, "link", "set", s_if, "up")
            _ip("-n", ns, "link", "set", c_if, "up")
            h.clients[client] = ns
            h.server_address[client] = f"10.{subnet}.{i}.1"
            h.links[client] = c_if
        yield h
    finally:
        for ns in made:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
