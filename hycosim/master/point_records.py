"""Each macro-step point to the observers (the recorder among them): the point the loop is at,
the base points inside a batched release, and the point where a node's model ended the run;
rollbacks and the run's end to the same observers."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from hycosim.core.schema import Project
from hycosim.master.barrier import Barrier
from hycosim.master.observers import Observer, RecordedPoint
from hycosim.master.record_files import RecordError
from hycosim.master.run_state import Point, RunError, Seen


class PointRecords:
    """Every point to the observers: the master's own first (the recorder, the status answer),
    then the ones a user added. Each is told through the same three calls."""

    def __init__(self, project: Project, barrier: Barrier, own: list[Observer]):
        self.project, self.barrier = project, barrier
        self.observers: list[Observer] = list(own)
        self._told = [(o, o.step_complete) for o in self.observers]
        self._point = RecordedPoint(project)

    def add_observer(self, observer: Observer) -> None:
        """Tell ``observer`` of every point from now on, after the observers already there."""
        self.observers.append(observer)
        self._told.append((observer, observer.step_complete))

    def _record(self, step: int, t: float, mode: str, outputs: dict[str, list[Any]],
                inputs: dict[str, list[Any]], stepped: list[str] | None, wait_s: float, holder: str,
                lateness_s: float | None, arrivals: dict[str, float], ages: dict[str, float | None],
                takes: int = 1, released: float | None = None) -> None:
        """Point ``step`` to every observer: its values, and how the step to it went."""
        point = self._point
        point.mode, point.outputs, point.inputs, point.stepped = mode, outputs, inputs, stepped
        point.wait_s, point.holder, point.lateness_s = wait_s, holder, lateness_s
        point.arrivals, point.ages, point.takes, point.released = arrivals, ages, takes, released
        self.tell(step, t, point)

    def tell(self, step: int, t: float, point: RecordedPoint) -> None:
        """Point ``step``, filled in, to every observer (a user's that fails ends the run, named)."""
        for observer, step_complete in self._told:
            try:
                step_complete(step, t, point)
            except (RecordError, RunError):
                raise
            except Exception as exc:  # a user's observer: anything may go wrong in it
                raise self._failed(observer, "step_complete", step, exc) from exc

    def restored(self, step: int, t: float) -> None:
        """The run went back to its checkpoint at point ``step``: every observer told (the
        recorder cuts its files back to it first)."""
        for observer in self.observers:
            try:
                observer.state_restored(step, t)
            except (RecordError, RunError):
                raise
            except Exception as exc:  # a user's observer
                raise self._failed(observer, "state_restored", step, exc) from exc

    def ended(self, status: str, log: Any) -> None:
        """The run is over: every observer told, the recorder first (it closes the records and
        never raises); one that fails is logged, for the run is over and recorded."""
        for observer in self.observers:
            try:
                observer.run_ended(status)
            except Exception:  # noqa: BLE001 - a broken observer changes nothing now
                log.exception("observer failed at the run's end", observer=type(observer).__name__)

    @staticmethod
    def _failed(observer: Observer, what: str, step: int, exc: Exception) -> RunError:
        """A user's observer that failed: the run ends, named, records kept."""
        return RunError(f"observer {type(observer).__name__}: {what} failed at step {step}: "
                        f"{type(exc).__name__}: {exc}")

    def point(self, p: Point, seen: Seen, released: float) -> None:
        """Point p as the loop saw it, with the inputs the step from it is taken on (an iterated
        step's last) and how the step to it went; ``released``: when the step from it was."""
        self._record(p.k, p.t, seen.mode, seen.outputs, self.barrier.router.inputs, seen.stepped,
                     p.wait, seen.holder, seen.lateness, p.arrivals, seen.ages, p.takes, released)

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
            self._record(k + i, times[i], mode, outputs, b.router.inputs, b.coupling.due(k + i),
                         0.0, holder, None, came, {})
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
        self._record(k + after, at, mode, outputs, b.router.inputs, None,
                     0.0, ended["node"], None, ending.arrivals if on_grid else {}, {})
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
