"""Zenoh key expressions of one project; every process derives them the same way."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ProjectKeys:
    """Keys under ``hycosim/<project>``.

    ``up/<node>`` carries frames from a node to the server, ``down`` the server's frames
    to every node (one message per macro step for all of them: the Zenoh binding's
    per-message cost, not bandwidth, bounds the barrier), ``alive/<node>`` the liveliness
    tokens, ``status`` the server's status queryable.
    """

    project: str

    @property
    def root(self) -> str:
        """The key every key of the project lies under, ``hycosim/<project>``."""
        return f"hycosim/{self.project}"

    def up(self, node: str) -> str:
        """Key a node publishes its outputs and samples on."""
        return f"{self.root}/up/{node}"

    @property
    def up_all(self) -> str:
        """Every node's ``up`` key: what the server subscribes to."""
        return f"{self.root}/up/*"

    @property
    def down(self) -> str:
        """Key the server publishes starts, releases and stops on."""
        return f"{self.root}/down"

    def alive(self, node: str) -> str:
        """Liveliness token key of a node (or of the server, named ``_server``)."""
        return f"{self.root}/alive/{node}"

    @property
    def alive_all(self) -> str:
        """Every liveliness token of the project: what the server watches."""
        return f"{self.root}/alive/*"

    @property
    def status(self) -> str:
        """The key of the server's status queryable."""
        return f"{self.root}/status"

    @staticmethod
    def last_chunk(key: str) -> str:
        """The node name at the end of an ``up/<node>`` or ``alive/<node>`` key."""
        return key.rsplit("/", 1)[-1]


SERVER_TOKEN = "_server"
