"""Opening an FMU as a node's entry says: the one place that knows both kinds of instance.

A co-simulation FMU steps itself (:class:`~hycosim.fmi.instance.FmuInstance`, FMI 1.0's
:class:`~hycosim.fmi.fmi1.Fmi1Instance`); a Model
Exchange FMU is integrated by the node (:class:`~hycosim.fmi.model_exchange.MeInstance`, built on
the former). Kept apart from both so that neither module imports the other in a circle.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hycosim.core.schema import Node
from hycosim.fmi.fmi1 import Fmi1Instance, Fmi1MeInstance
from hycosim.fmi.instance import FmuInstance
from hycosim.fmi.loader import MODEL_EXCHANGE, check_fmu
from hycosim.fmi.model_exchange import MeInstance


def open_fmu(path: Path, node: Node, parameters: dict[str, Any], stop_time: float | None = None) -> FmuInstance:
    """Instantiate the FMU as the node's entry says: a co-simulation slave, or a Model Exchange
    model with its integrator (``stop_time``: the run's, for the default largest step)."""
    mapping = check_fmu(path, node, parameters)
    if mapping.interface == MODEL_EXCHANGE:
        kind = Fmi1MeInstance if mapping.md.fmiVersion == "1.0" else MeInstance
        return kind(path, node, parameters, mapping, stop_time)
    if mapping.md.fmiVersion == "1.0":
        return Fmi1Instance(path, node, parameters, mapping)
    return FmuInstance(path, node, parameters, mapping)
