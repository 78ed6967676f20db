"""Deprecated since 0.3.0: the node interface is :mod:`hycosim.node` (``from hycosim.node
import Node``). This module re-exports it for one release."""

import warnings

from hycosim.node.interface import (AsyncSource, Node, NodeContext, NodeModelError, SimulationEnded,
                                    missing_state_methods, pack_state, unpack_state)

__all__ = ["AsyncSource", "Node", "NodeContext", "NodeModelError", "SimulationEnded", "missing_state_methods",
           "pack_state", "unpack_state"]

warnings.warn("hycosim.clients.node is deprecated since 0.3.0 and goes in 0.4.0: from hycosim.node import Node",
              DeprecationWarning, stacklevel=2)
