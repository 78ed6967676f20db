"""Nodes: the interface a simulator implements (:class:`Node`, :class:`AsyncSource`), the
runtime that attaches one to a run, the loader that finds it, FMU nodes, replay and the
reference models."""

from hycosim.node.interface import (AsyncSource, Node, NodeContext, NodeModelError, SimulationEnded, pack_state,
                                    unpack_state)

__all__ = ["AsyncSource", "Node", "NodeContext", "NodeModelError", "SimulationEnded", "pack_state", "unpack_state"]
