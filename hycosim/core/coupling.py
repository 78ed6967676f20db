"""How a project's stepping nodes are coupled: each node's rate, and the Gauss-Seidel order.

Jacobi (the default, the paper's scheme): every node due at a macro-step point steps at once,
on inputs routed from the outputs at that point. Gauss-Seidel: within a macro step the nodes
step one after the other, each on inputs routed from the outputs its predecessors have
already advanced to the step's end; a node comes after the nodes it reads from.

Multi-rate: a node whose entry gives ``stepSize``, an integer multiple m of the base
``coSimulation.stepSize``, steps at every m-th base point (from startTime) over m base steps
(the last one cut at stopTime); its outputs hold between its steps, and its inputs are those
routed at its step's start.

Batched releases: between two points where some link needs an exchange, nothing a node reads
changes, so the server releases the nodes once for all the base steps in between (STEPS) and
each answers once (BATCH) with its outputs after each of its own steps: the same values,
recorded at every base point, for a fraction of the messages. See :func:`batch_span`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hycosim.core.schema import Issue, PortType, Project, Route
from hycosim.core.frames import MAX_BATCH

# A BATCH carries one list of outputs per step of its node: on the low-latency transport
# (frames of at most 32 KiB) a span keeps each node's under half of that, with numbers
# packed in 9 bytes and a text or binary value counted as 64 (a larger one needs
# "lowLatency": false, batched or not).
BATCH_BYTES = 16 * 1024

# How far node stepSize / base stepSize may be from an integer (relative): decimal step
# sizes (0.1 / 0.01) are not exact in binary.
RATIO_TOLERANCE = 1e-9


@dataclass(frozen=True)
class CouplingPlan:
    """The coupling of one project's stepping nodes (asynchronous sources take no part)."""

    scheme: str  # "jacobi" or "gauss-seidel"
    rates: dict[str, int]  # node → its step as a multiple of the base step
    order: tuple[str, ...]  # Gauss-Seidel: the order nodes step in; Jacobi: the file's order
    multirate: bool = False  # some node steps slower than the base (read at every step: a plain field)
    batch: int = 1  # base steps a release may span (1: one release per base point)
    unbatched: str = ""  # why a multi-rate run releases every base point, if it does

    @property
    def period(self) -> int:
        """Base steps between points where every node is due (checkpoints are taken there)."""
        return math.lcm(*self.rates.values()) if self.rates else 1

    def due(self, k: int) -> list[str]:
        """The nodes that start a step at base point k, in order."""
        return [n for n in self.order if k % self.rates[n] == 0]

    def describe(self, cannot_batch: list[str] | None = None) -> str:
        """One line for meta.json and the report (``cannot_batch``: the nodes that turned out
        unable to take batched releases, which the run then does without)."""
        text = "Gauss-Seidel, order " + " → ".join(self.order) if self.scheme == "gauss-seidel" else "Jacobi"
        slow = {n: m for n, m in self.rates.items() if m > 1}
        if slow:
            text += "; multi-rate: " + ", ".join(f"{n} every {m} base steps" for n, m in slow.items())
            unbatched = f"{', '.join(cannot_batch)} cannot take batched steps" if cannot_batch else self.unbatched
            text += (f"; releases batched over {self.batch} base steps" if self.batch > 1 and not cannot_batch
                     else f"; one release per base point ({unbatched})" if unbatched else "")
        return text


def rate_of(step: float | None, base: float) -> int | None:
    """A node's stepSize as a multiple of the base step; None when it is not an integer multiple."""
    if step is None:
        return 1
    ratio = step / base
    if not math.isfinite(ratio) or ratio < 0.5:  # 1e300 / 1e-10 overflows to infinity
        return None
    m = round(ratio)
    if abs(ratio - m) > RATIO_TOLERANCE * ratio:
        return None
    return m


def _reads_from(project: Project, routes: list[Route]) -> dict[str, set[str]]:
    """Stepping node → the stepping nodes it reads from over links active in any mode."""
    stepping = {n.nodeName for n in project.stepping_nodes()}
    reads: dict[str, set[str]] = {n: set() for n in stepping}
    for r in routes:
        if r.src_node in stepping and r.dst_node in stepping and r.src_node != r.dst_node:
            reads[r.dst_node].add(r.src_node)
    return reads


def derived_order(project: Project, routes: list[Route]) -> tuple[list[str], list[str]]:
    """The Gauss-Seidel order the links give: (order, the nodes on cycles, which leave no order).

    Among nodes free to go next, the one listed first in the file goes first, so the order is
    the same on every host.
    """
    reads = _reads_from(project, routes)
    left = [n.nodeName for n in project.stepping_nodes()]
    order: list[str] = []
    while left:
        ready = next((n for n in left if not (reads[n] - set(order))), None)
        if ready is None:
            return order, [n for n in left if _on_cycle(n, reads, set(left))]
        order.append(ready)
        left.remove(ready)
    return order, []


def _on_cycle(node: str, reads: dict[str, set[str]], among: set[str]) -> bool:
    """Whether ``node`` reads, through links among ``among``, from itself."""
    seen: set[str] = set()
    todo = [n for n in reads[node] if n in among]
    while todo:
        n = todo.pop()
        if n == node:
            return True
        if n not in seen:
            seen.add(n)
            todo.extend(m for m in reads[n] if m in among)
    return False


def batch_span(project: Project, routes: list[Route], rates: dict[str, int]) -> tuple[int, str]:
    """How many base steps one release may span in a multi-rate Jacobi run, and why 1 if it is.

    A link from a node of rate a to one of rate b needs an exchange every max(a, b) base steps:
    the reader takes its inputs only at its own steps, and the writer's outputs change only at
    its own. So between multiples of P, the greatest common divisor of those periods, no input
    any node steps on changes, and a release can span P base steps, provided every rate divides
    P or is a multiple of it (a node then takes whole steps inside a batch, or whole batches
    inside its step). Events, iteration, error control and checkpoints act at every base
    point, real-time pacing paces every one, and asynchronous sources change inputs at any
    time: with any of them, P is 1. On the low-latency transport the span is also kept small
    enough for each node's BATCH to fit a frame.
    """
    cosim = project.coSimulation
    for on, why in ((not cosim.batchReleases, "coSimulation.batchReleases is false"),
                    (cosim.coupling != "jacobi", "Gauss-Seidel"), (bool(project.events), "events"),
                    (cosim.iterate is not None, "iterative coupling"),
                    (cosim.algorithm is not None, "a master algorithm of the user's"),
                    (cosim.stepControl is not None, "an error-controlled step"),
                    (cosim.checkpointEvery is not None, "checkpoints"),
                    # Paced runs step each node at its points' wall times, not in bursts.
                    (cosim.real_time_factor() is not None, "real-time pacing"),
                    (bool(project.async_nodes()), "asynchronous sources")):
        if on:
            return 1, why
    periods = [max(rates[r.src_node], rates[r.dst_node]) for r in routes if r.src_node in rates and r.dst_node in rates]
    span = math.gcd(*periods) if periods else math.lcm(*rates.values())
    per_step = {n.nodeName: 4 + sum(64 if p.type in (PortType.STRING, PortType.BINARY) else 9 for p in n.output)
                for n in project.stepping_nodes()}
    budget = BATCH_BYTES if cosim.lowLatency else math.inf

    def fits(p: int) -> bool:
        return all(-(-p // rates[n]) * size <= budget for n, size in per_step.items())

    # The largest span that fits a frame and that every rate divides or is a multiple of.
    span = next((p for p in range(min(span, MAX_BATCH), 0, -1)
                 if span % p == 0 and all(p % m == 0 or m % p == 0 for m in rates.values()) and fits(p)), 1)
    return span, "" if span > 1 else "the links exchange at every base point"


def plan(project: Project, routes: list[Route]) -> CouplingPlan:
    """The coupling of a valid project (:func:`coupling_issues` found nothing)."""
    cosim = project.coSimulation
    rates = {n.nodeName: rate_of(n.stepSize, cosim.stepSize) or 1 for n in project.stepping_nodes()}
    if cosim.coupling == "gauss-seidel":
        order = tuple(cosim.order) if cosim.order else tuple(derived_order(project, routes)[0])
    else:
        order = tuple(rates)
    multirate = any(m > 1 for m in rates.values())
    batch, unbatched = batch_span(project, routes, rates) if multirate else (1, "")
    return CouplingPlan(cosim.coupling, rates, order, multirate, batch, unbatched)


def _slower(nodes: list[str]) -> str:
    return f"{', '.join(nodes)} {'steps' if len(nodes) == 1 else 'step'} slower than the base"


def _retry_issues(project: Project, multirate: list[str]) -> list[Issue]:
    """What iterative coupling and the error-controlled step, which both take steps again after
    a rollback, do not work with."""
    cosim = project.coSimulation
    issues: list[Issue] = []
    control = cosim.stepControl
    if control is not None and control.minStep > control.maxStep:
        issues.append(Issue("coSimulation.stepControl", f"minStep {control.minStep:g} s is above maxStep "
                            f"{control.maxStep:g} s", "minStep ≤ stepSize ≤ maxStep"))
    for key in ("iterate", "stepControl"):
        if cosim.algorithm is not None and getattr(cosim, key) is not None:
            issues.append(Issue(f"coSimulation.{key}", f"coSimulation.algorithm {cosim.algorithm!r} takes the place "
                                f"of {key}", f"leave out coSimulation.{key} or coSimulation.algorithm"))
    if cosim.iterate is not None and control is not None:
        issues.append(Issue("coSimulation.stepControl", "iterative coupling and an error-controlled step cannot be "
                            "combined yet", "leave out one of coSimulation.iterate and coSimulation.stepControl"))
    for key, what in (("iterate", "iterative coupling"), ("stepControl", "an error-controlled step")):
        if getattr(cosim, key) is None:
            continue
        where = f"coSimulation.{key}"
        if cosim.coupling != "jacobi":
            issues.append(Issue(where, f"{what} works with Jacobi coupling only", '"coupling": "jacobi"'))
        if multirate:
            issues.append(Issue(where, f"{what} works with single-rate nodes only; {_slower(multirate)}",
                                "leave out the nodes' stepSize"))
        if cosim.eventTolerance is not None:
            issues.append(Issue(where, f"{what} and locating events by rollback cannot be combined",
                                "leave out coSimulation.eventTolerance"))
        played = [n.nodeName for n in project.paced_nodes()]
        if played:
            issues.append(Issue(where, f"{what} cannot take steps of a played recording again "
                                f"({', '.join(played)})", f"leave out coSimulation.{key} to replay it"))
    return issues


def coupling_issues(project: Project, routes: list[Route]) -> list[Issue]:
    """Every problem with the nodes' step sizes and the coupling's order, by JSON path."""
    issues: list[Issue] = []
    cosim = project.coSimulation
    multirate: list[str] = []
    for i, n in enumerate(project.nodeLists):
        if n.stepSize is None:
            continue
        where = f"nodeLists[{i}].stepSize"
        if n.asynchronous:
            issues.append(Issue(where, f"asynchronous node {n.nodeName!r} does not step",
                                "its samples come at their own times ('rate')"))
            continue
        m = rate_of(n.stepSize, cosim.stepSize)
        if m is None:
            near = n.stepSize / cosim.stepSize
            example = f" (e.g. {max(1, round(near)) * cosim.stepSize:g})" if math.isfinite(near) else ""
            issues.append(Issue(where, f"node {n.nodeName!r} steps {n.stepSize:g} s, which is not an integer "
                                f"multiple of coSimulation.stepSize {cosim.stepSize:g} s",
                                f"a multiple of the base step{example}"))
        elif m > 1:
            multirate.append(n.nodeName)
    if multirate and cosim.eventTolerance is not None:
        issues.append(Issue("coSimulation.eventTolerance", f"locating events by rollback works with single-rate "
                            f"nodes only; {_slower(multirate)}",
                            "leave eventTolerance out (crossings are then located to within one base step)"))
    issues.extend(_retry_issues(project, multirate))
    stepping = [n.nodeName for n in project.stepping_nodes()]
    if cosim.order is not None and cosim.coupling != "gauss-seidel":
        issues.append(Issue("coSimulation.order", "an order is for Gauss-Seidel coupling, and this project's "
                            "is Jacobi", '"coupling": "gauss-seidel", or leave order out'))
    if cosim.coupling != "gauss-seidel":
        return issues
    if multirate:
        issues.append(Issue("coSimulation.coupling", f"Gauss-Seidel coupling works with single-rate nodes only; "
                            f"{_slower(multirate)}", "Jacobi coupling, or one rate"))
    if cosim.eventTolerance is not None:
        issues.append(Issue("coSimulation.eventTolerance", "locating events by rollback works with Jacobi "
                            "coupling only", "leave eventTolerance out, or use Jacobi coupling"))
    played = [n.nodeName for n in project.paced_nodes()]
    if played:
        issues.append(Issue("coSimulation.coupling", f"Gauss-Seidel coupling cannot pace a played recording "
                            f"({', '.join(played)})", "Jacobi coupling to replay asynchronous sources"))
    if cosim.order is not None:
        known = set(stepping)
        unknown = [n for n in cosim.order if n not in known]
        for name in unknown:
            hint = ("it is an asynchronous source: those do not step" if name in {n.nodeName for n in project.nodeLists}
                    else f"stepping nodes are {', '.join(stepping)}")
            issues.append(Issue("coSimulation.order", f"names {name!r}, which is not a stepping node", hint))
        twice = sorted({n for n in cosim.order if cosim.order.count(n) > 1})
        if twice:
            issues.append(Issue("coSimulation.order", f"names {', '.join(twice)} more than once", "each node once"))
        missing = [n for n in stepping if n not in cosim.order]
        if missing:
            issues.append(Issue("coSimulation.order", f"leaves out {', '.join(missing)}",
                                "every stepping node once, in the order they step"))
        return issues
    _, cycle = derived_order(project, routes)
    if cycle:
        issues.append(Issue("coSimulation.order", f"the links make a cycle among {', '.join(cycle)}, so they give "
                            "no order to step in", "give coSimulation.order: a node listed before a node it reads "
                            "from reads that node's outputs at the step's start"))
    return issues


def algebraic_loops(routes: list[Route], feedthrough: dict[str, dict[str, set[str]]]) -> list[list[str]]:
    """The cycles of direct feedthrough: links (an output to an input) and, inside a node, an
    output that depends directly on an input (``feedthrough``: node → output → inputs). One
    cycle per knot of ports that reach each other, as "node.port" names from an output round
    to it again."""
    succ: dict[str, set[str]] = {}
    for r in routes:
        succ.setdefault(f"{r.src_node}.{r.src_port}", set()).add(f"{r.dst_node}.{r.dst_port}")
    for node, outs in feedthrough.items():
        for out, ins in outs.items():
            for i in ins:
                succ.setdefault(f"{node}.{i}", set()).add(f"{node}.{out}")
    loops: list[list[str]] = []
    covered: set[str] = set()
    for start in sorted(succ):
        if start in covered:
            continue
        path = _path_back(start, succ)
        if path is not None:
            loops.append(path)
            covered.update(path)
    return loops


def _path_back(start: str, succ: dict[str, set[str]]) -> list[str] | None:
    """The shortest path from ``start`` round to itself, or None (breadth first)."""
    came: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for port in frontier:
            for to in sorted(succ.get(port, ())):
                if to == start:
                    path = [port]
                    while path[-1] != start:
                        path.append(came[path[-1]])
                    return [*reversed(path), start]
                if to not in came:
                    came[to] = port
                    nxt.append(to)
        frontier = nxt
    return None
