"""Link routing: node outputs at a macro-step point → node inputs for the next step.

The routes of every mode are resolved once, so routing a step is a flat loop. An input
with no link active in the current mode keeps its last value (its start value at first).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Iterator, Mapping

from hycosim.core.schema import PortType

from hycosim.core.config import LoadedProject

from hycosim.master.async_sources import SampleHistory


@dataclass(frozen=True)
class _Hop:
    dst_node: str
    dst_index: int
    src_node: str
    src_index: int
    extrapolation: str
    convert: Callable[[Any], Any] | None
    label: str  # "dst_node.dst_port", for ages


def _linear(factor: float, offset: float) -> Callable[[Any], float]:
    """A link's linear transformation: input = factor·output + offset."""
    return lambda value: factor * value + offset


def _for_shape(convert: Callable[[Any], Any] | None, array: bool,
               element: int | None) -> Callable[[Any], Any] | None:
    """A hop's conversion of a scalar value made to fit what the hop carries: one element of an
    array (``element``), or every element of one (``array``)."""
    if element is not None:
        return (lambda value: value[element]) if convert is None else (lambda value: convert(value[element]))
    if array and convert is not None:
        return lambda value: [convert(x) for x in value]
    return convert


class OutputView(Mapping[tuple[str, str], Any]):
    """Read-only view of the outputs at a macro-step point, keyed (node, port), for guards."""

    def __init__(self, index: Mapping[tuple[str, str], tuple[str, int]], outputs: Mapping[str, list[Any]]):
        self._index = index
        self._outputs = outputs

    def __getitem__(self, key: tuple[str, str]) -> Any:
        node, i = self._index[key]
        return self._outputs[node][i]

    def __iter__(self) -> Iterator[tuple[str, str]]:
        return iter(self._index)

    def __len__(self) -> int:
        return len(self._index)


class Router:
    """The links as index plans: which output feeds which input in each mode, and the inputs routed at
    each point (per node, a list in its ports' order)."""

    def __init__(self, loaded: LoadedProject):
        project = loaded.project
        self.inputs: dict[str, list[Any]] = {
            n.nodeName: [p.start_value() for p in n.input] for n in project.nodeLists}
        self.output_index = {(n.nodeName, p.name): (n.nodeName, i)
                             for n in project.nodeLists for i, p in enumerate(n.output)}
        self._async = {n.nodeName for n in project.async_nodes()}
        # Inputs a scenario overrides: node → [(input index, value)], written over what the links bring.
        self.pins: dict[str, list[tuple[int, Any]]] = {}
        self._plans: dict[str, list[_Hop]] = {}
        for mode in project.modes():
            hops = []
            for r in loaded.routes:
                if not r.active(mode):
                    continue
                dst = project.node(r.dst_node)
                src = project.node(r.src_node)
                dst_port = dst.port(r.dst_port)
                src_port = src.port(r.src_port)
                widen = None
                if r.transform is not None:
                    widen = _linear(*r.transform)
                elif dst_port.type is PortType.REAL and src_port.type is not PortType.REAL:
                    widen = float
                elif dst_port.type is PortType.INTEGER and src_port.type is PortType.BOOLEAN:
                    widen = int
                widen = _for_shape(widen, src_port.shape is not None, r.src_element)
                hops.append(_Hop(r.dst_node, dst.input_names().index(r.dst_port), r.src_node,
                                 src.output_names().index(r.src_port), r.extrapolation, widen,
                                 f"{r.dst_node}.{r.dst_port}"))
            self._plans[mode] = hops
        # Each mode's hops that copy a stepping node's output as it is, as (destination node,
        # input index, source node, output index), and the rest (a conversion, an asynchronous
        # source): the first kind is most of a run's routing, a line of Python a hop.
        self._copies = {mode: [(h.dst_node, h.dst_index, h.src_node, h.src_index) for h in hops
                               if h.convert is None and h.src_node not in self._async]
                        for mode, hops in self._plans.items()}
        self._others = {mode: [h for h in hops if h.convert is not None or h.src_node in self._async]
                        for mode, hops in self._plans.items()}
        # The same hops by destination node, for Gauss-Seidel's routing into one node at a time.
        self._into = {mode: {n.nodeName: [h for h in hops if h.dst_node == n.nodeName] for n in project.nodeLists}
                      for mode, hops in self._plans.items()}

    def route(self, mode: str, t: float, outputs: Mapping[str, list[Any]],
              histories: Mapping[str, SampleHistory]) -> dict[str, float | None]:
        """Update ``self.inputs`` for the mode; return the age of every asynchronous value used."""
        ages: dict[str, float | None] = {}
        inputs = self.inputs
        for dst, i, src, j in self._copies[mode]:  # one input feeds from one link a mode: any order
            inputs[dst][i] = outputs[src][j]
        for hop in self._others[mode]:
            if hop.src_node in self._async:
                value, age = histories[hop.src_node].value_at(hop.src_index, t, hop.extrapolation)
                ages[hop.label] = age
            else:
                value = outputs[hop.src_node][hop.src_index]
            inputs[hop.dst_node][hop.dst_index] = value if hop.convert is None else hop.convert(value)
        if self.pins:
            self._pin(inputs)
        return ages

    def _pin(self, inputs: dict[str, list[Any]]) -> None:
        for node, pinned in self.pins.items():
            row = inputs[node]
            for i, value in pinned:
                row[i] = value

    def candidate(self, mode: str, outputs: Mapping[str, list[Any]]) -> dict[str, list[Any]]:
        """The inputs :meth:`route` would give from stepping nodes' ``outputs`` now, as a copy
        (``self.inputs`` unchanged; asynchronous values as the last route brought them)."""
        inputs = {n: list(v) for n, v in self.inputs.items()}
        for hop in self._plans[mode]:
            if hop.src_node not in self._async:
                value = outputs[hop.src_node][hop.src_index]
                inputs[hop.dst_node][hop.dst_index] = value if hop.convert is None else hop.convert(value)
        self._pin(inputs)
        return inputs

    def route_into(self, node: str, mode: str, outputs: Mapping[str, list[Any]]) -> None:
        """Update ``self.inputs[node]`` alone from stepping nodes' outputs (Gauss-Seidel, within a
        step: its asynchronous inputs stay as :meth:`route` brought them to the step's start)."""
        inputs = self.inputs[node]
        for hop in self._into[mode][node]:
            if hop.src_node not in self._async:
                value = outputs[hop.src_node][hop.src_index]
                inputs[hop.dst_index] = value if hop.convert is None else hop.convert(value)
        for i, value in self.pins.get(node, ()):
            inputs[i] = value
