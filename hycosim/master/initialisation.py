"""The initialisation phase: the nodes' outputs at the start made consistent with their inputs.

Each node answers the START with its outputs at t0 as its setup made them, from its inputs'
start values. A node whose start outputs depend directly on inputs (an FMU's
``InitialUnknowns``, a Python model's ``start_feedthrough``; its HELLO says which) would then
start from outputs that disagree with the inputs the links give it, and a chain of such nodes
would start one macro step late per link. Here the server gives such nodes their linked inputs
at t0 (INIT) and takes their outputs again, in the order the dependencies give: a node after
the nodes it reads from; a cycle of them (an algebraic loop at the start) is swept in the
project's node order until its outputs stop changing. An FMU is inside its initialisation mode
all the while, as FMI lays out (ECOS and libcosim do the same): once every node has its start
inputs, the nodes still in that mode get their inputs once more, leave it together, and
answer with the outputs the first point records (an FMU that computes its outputs only when it
leaves that mode, as pythonfmu's commonly do, starts from its linked inputs).

This module plans and judges; :func:`run` sends and gathers through the barrier.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import structlog

from hycosim.core import frames
from hycosim.core.config import LoadedProject
from hycosim.core.coupling import algebraic_loops
from hycosim.core.schema import Route
from hycosim.master.run_state import RunError


@dataclass(frozen=True)
class Group:
    """Nodes initialised together: one node, or a cycle swept until a fixed point."""

    nodes: tuple[str, ...]
    loop: bool


def checked_feedthrough(said: Any, inputs: list[str], outputs: list[str]) -> dict[str, set[str]]:
    """A HELLO's ``startFeedthrough`` (output port → the input ports it reads at the start)
    within the node's ports: anything else in it is left out (a HELLO is a receiver's input)."""
    if type(said) is not dict:
        return {}
    ins, outs = set(inputs), set(outputs)
    checked: dict[str, set[str]] = {}
    for out, reads in said.items():
        if type(out) is str and out in outs and type(reads) is list:
            read = {i for i in reads if type(i) is str and i in ins}
            if read:
                checked[out] = read
    return checked


def plan(routes: list[Route], mode: str, feedthrough: dict[str, dict[str, set[str]]],
         order: list[str]) -> list[Group]:
    """The groups to initialise, in order: the nodes (of ``order``, the stepping nodes in the
    project's order) one of whose start outputs reads an input a link active in ``mode`` feeds
    from another stepping node. A node comes after every node whose changing outputs it reads;
    nodes that read each other's (directly or round a cycle) form one looping group."""
    stepping = set(order)
    reads = {n: set().union(*outs.values()) for n, outs in feedthrough.items() if n in stepping and outs}
    active = [r for r in routes if r.active(mode) and r.src_node in stepping]
    taking = {r.dst_node for r in active if r.dst_port in reads.get(r.dst_node, ())}
    changing = {n: {o for o, ins in feedthrough[n].items() if ins} for n in taking}
    after: dict[str, set[str]] = {n: set() for n in taking}  # node → the taking nodes it reads changing outputs of
    for r in active:
        if r.dst_node in taking and r.src_node in taking and r.src_port in changing[r.src_node] \
                and r.dst_port in reads[r.dst_node]:
            after[r.dst_node].add(r.src_node)
    ranked = [n for n in order if n in taking]
    return [Group(tuple(sorted(c, key=ranked.index)), len(c) > 1 or c[0] in after[c[0]])
            for c in _components(ranked, after)]


def _components(nodes: list[str], after: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of the graph (an edge from each node to those in
    ``after[node]``), each after the components it reaches (Tarjan's order)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(after[v], key=nodes.index):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            found.append(component)

    for v in nodes:
        if v not in index:
            visit(v)
    return found


def residuals(before: dict[str, list[Any]], now: dict[str, list[Any]], names: dict[str, list[str]]
              ) -> dict[str, float]:
    """Each output's change over a sweep, as "node.port" → |new − old| / max(1, |old|) (a value
    that is no number: 0 if unchanged, else infinity)."""
    out: dict[str, float] = {}
    for node, old in before.items():
        for port, a, b in zip(names[node], old, now[node]):
            if type(a) is list and type(b) is list and len(a) == len(b):  # an array port: its worst element
                out[f"{node}.{port}"] = max(map(_change, a, b), default=0.0)
            else:
                out[f"{node}.{port}"] = _change(a, b)
    return out


def _change(a: Any, b: Any) -> float:
    if type(a) in (int, float) and type(b) in (int, float):
        return abs(b - a) / max(1.0, abs(a)) if math.isfinite(a) and math.isfinite(b) else (
            0.0 if a == b else math.inf)
    return 0.0 if a == b else math.inf


def describe_loop(group: Group, routes: list[Route], feedthrough: dict[str, dict[str, set[str]]]) -> str:
    """The loop a group holds, as "a.y → b.u → b.y → a.u → a.y" (the nodes, if the ports make none)."""
    inside = set(group.nodes)
    loops = algebraic_loops([r for r in routes if r.src_node in inside and r.dst_node in inside],
                            {n: feedthrough.get(n, {}) for n in inside})
    return "; ".join(" → ".join(loop) for loop in loops) or ", ".join(group.nodes)


def run(barrier: Any, loaded: LoadedProject, mode: str) -> None:
    """The initialisation phase over ``barrier`` (a master.barrier.Barrier): each node whose
    start outputs read linked inputs is given them at t0 and answers with its outputs again, in
    dependency order; a loop is swept until its outputs settle, or the run fails naming it
    (RunError). What was done goes to the metadata (``initialisation``)."""
    project = loaded.project
    t0, settings = project.coSimulation.startTime, project.coSimulation.initialize
    stepping, router, outputs = barrier.stepping, barrier.router, barrier.outputs
    capabilities = barrier.members.capabilities
    feedthrough = {n: checked_feedthrough(capabilities.get(n, {}).get("startFeedthrough"),
                                          project.node(n).input_names(), project.node(n).output_names())
                   for n in stepping}
    groups = plan(loaded.routes, mode, feedthrough, stepping)
    done: list[dict[str, Any]] = []
    barrier.meta["initialisation"] = done
    holding = [n for n in stepping if capabilities.get(n, {}).get("initializationMode") is True]
    if not groups and not holding:
        return
    router.route(mode, t0, outputs, barrier.histories)  # the sources' values at t0 too
    names = {n: project.node(n).output_names() for n in stepping}
    log = structlog.get_logger("server")
    for group in groups:
        for sweep in range(1, (settings.maxIterations if group.loop else 1) + 1):
            before = {n: list(outputs[n]) for n in group.nodes}
            for node in group.nodes:
                router.route_into(node, mode, outputs)
                barrier.release.put(frames.encode(frames.INIT, t0, {node: list(router.inputs[node])}, False))
                barrier.messages["releases"] += 1
                barrier.gather(0, time.perf_counter(), {node}, paced=False)
            if not group.loop:
                break
            change = residuals(before, outputs, names)
            if max(change.values(), default=0.0) <= settings.tolerance:
                break
        else:
            worst = sorted(change.items(), key=lambda item: -item[1])[:4]
            loop = describe_loop(group, loaded.routes, feedthrough)
            raise RunError(
                f"initialisation: the algebraic loop {loop} did not settle in {settings.maxIterations} "
                "sweeps (coSimulation.initialize.maxIterations); "
                "its last changes: " + ", ".join(f"{port} {value:.3g}" for port, value in worst)
                + f" (tolerance {settings.tolerance:g})")
        done.append({"nodes": list(group.nodes), "loop": group.loop, "sweeps": sweep})
        log.info("initialised", nodes=list(group.nodes), sweeps=sweep)
    if holding:
        leave(barrier, holding, t0, mode)
        done.append({"nodes": holding, "left": "initialization mode"})


def leave(barrier: Any, nodes: list[str], t0: float, mode: str) -> None:
    """The nodes that are still in their models' initialisation mode (FMUs) get their inputs at
    t0 as the links carry the start outputs now, all at once, and leave it; their answers are
    the outputs the run's first point records."""
    router, outputs = barrier.router, barrier.outputs
    for node in nodes:
        router.route_into(node, mode, outputs)
    barrier.release.put(frames.encode(frames.INIT, t0, {n: list(router.inputs[n]) for n in nodes}, True))
    barrier.messages["releases"] += 1
    barrier.gather(0, time.perf_counter(), set(nodes), paced=False)
