"""Each macro-step point into the records and to the observers: the point the loop is at, the
base points inside a batched release, and the point where a node's model ended the run."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from hycosim.core.schema import Project
from hycosim.master.barrier import Barrier
from hycosim.master.observers import Observer, PointValues
from hycosim.master.recorder import Recorder
from hycosim.master.run_state import Point, RunError, Seen


class PointRecords:
    """Rows and timings for the recorder; every row to the observers too, once one is added."""

    def __init__(self, project: Project, recorder: Recorder, barrier: Barrier):
        self.project, self.recorder, self.barrier = project, recorder, barrier
        self.observers: list[Observer] = []
        self._values = PointValues(project)
        # A row goes to the recorder alone until an observer is added.
        self.row = recorder.row

    def add_observer(self, observer: Observer) -> None:
        self.observers.append(observer)
        self.row = self._row_observed

    def _row_observed(self, step: int, t: float, mode: str, outputs: dict[str, list[Any]],
                      inputs: dict[str, list[Any]], stepped: list[str] | None = None) -> None:
        self.recorder.row(step, t, mode, outputs, inputs, stepped)
        values = self._values.at(outputs, inputs)
        for observer in self.observers:
            self.tell(observer, "step_complete", step, t, values)

    def tell(self, observer: Observer, what: str, *args: Any) -> None:
        """Call an observer; its failure ends the run, named, records kept."""
        try:
            getattr(observer, what)(*args)
        except Exception as exc:  # a user's observer: anything may go wrong in it
            raise RunError(f"observer {type(observer).__name__}: {what} failed at step {self.barrier.point}: "
                           f"{type(exc).__name__}: {exc}") from exc

    def point(self, p: Point, seen: Seen) -> None:
        """Point p as the loop saw it, with the inputs the step from it is taken on (an iterated
        step's last) and how the step to it went."""
        self.row(p.k, p.t, seen.mode, seen.outputs, self.barrier.router.inputs, seen.stepped)
        self.recorder.timing(p.k, p.t, p.wait, seen.holder, seen.lateness, p.arrivals, seen.ages, p.takes)

    def inside(self, k: int, times: list[float], mode: str, at_k: dict[str, list[Any]],
               arrivals: dict[str, float]) -> dict[str, list[Any]]:
        """The base points inside the batched release from point k, each with the outputs every
        node had there (a node's after each of its own steps, held between) and the inputs
        they route to: what a release per base point would have recorded. Their timing: no
        wait of their own (the batch's is at its end), and for each node whose step ended
        there, when the frame with its outputs came. Return the outputs at the last."""
        b = self.barrier
        outputs = dict(at_k)
        holder = max(arrivals, key=arrivals.get) if arrivals else ""
        for i in range(1, len(times) - 1):
            came = {}
            for node, values in self._steps_ending_at(i):
                outputs[node] = values
                came[node] = arrivals[node]
            b.router.route(mode, times[i], outputs, b.histories)
            self.row(k + i, times[i], mode, outputs, b.router.inputs, b.coupling.due(k + i))
            self.recorder.timing(k + i, times[i], 0.0, holder, None, came, {})
        return outputs

    def end(self, k: int, mode: str, at_k: dict[str, list[Any]], times: list[float]) -> None:
        """A node's model ended the run in the release from point k over the base points
        ``times`` ([t, t + h] for one step). Inside a batch, record the points its steps before
        reached (every other node's batch reached them too), as one release per base point
        would have. Then the point where it ended, as FMPy records an FMU that terminates: its
        outputs there; the others' at that point if it is the next one (their outputs for the
        step that ends there came), else held from the last recorded point, as the links hold
        them between points. Nothing is added where the node gave no outputs or ended outside
        the step after the last recorded point (a slower node's)."""
        b = self.barrier
        ending = b.ending
        ended = ending.by
        assert ended is not None
        reached, held = 0, at_k
        if len(times) > 2:
            reached = min([len(b.ledger.earlier[n]) * b.coupling.rates[n] for n in ending.inside]
                          + [len(times) - 2])
            if reached > 0:
                held = self.inside(k, times[:reached + 2], mode, at_k, ending.arrivals)
                ended["step"] = k + reached
        tol = 1e-9 * self.project.coSimulation.stepSize
        after, t_end = reached + 1, ended["t"]
        if ending.values is None or not times[reached] + tol < t_end <= times[after] + tol:
            return
        on_grid = t_end >= times[after] - tol
        outputs = dict(self._outputs_inside(after, times, held) if on_grid else held)
        outputs[ended["node"]] = ending.values
        at = times[after] if on_grid else t_end
        b.router.route(mode, at, outputs, b.histories)
        self.row(k + after, at, mode, outputs, b.router.inputs, None)
        self.recorder.timing(k + after, at, 0.0, ended["node"], None, ending.arrivals if on_grid else {}, {})
        ended["step"] = k + after

    def _outputs_inside(self, i: int, times: list[float], held: dict[str, list[Any]]) -> dict[str, list[Any]]:
        """Every node's outputs at base point i of the release over ``times`` that ended early
        (``held``: at point i - 1): the release's end is what the nodes answered; inside a
        batch, those of each node whose own step ended there."""
        if i == len(times) - 1:
            return self.barrier.outputs
        return {**held, **dict(self._steps_ending_at(i))}

    def _steps_ending_at(self, i: int) -> Iterator[tuple[str, list[Any]]]:
        """Inside the batched release being gathered: each node whose own step ends at base
        point i (a node that ended the run, up to its last step before), and its outputs there."""
        b = self.barrier
        for node, earlier in b.ledger.earlier.items():
            m = b.coupling.rates[node]
            if i % m == 0 and i // m - 1 < len(earlier):
                yield node, earlier[i // m - 1]
