"""Observers: what sees a run's points as they are recorded, as libcosim's observers do.

An :class:`Observer` is told of every point the run records (the values ``values.csv`` holds
there: each output as its node stepped it, each input as routed), of a rollback to a
checkpoint (the points after it are taken again), and of the run's end. The master's own
parts that follow the points are observers too, told first: the recorder (master.recorder,
CSV or Parquet tables) and, where anyone can ask for it, the status answer that ``hycosim
status`` and the dashboard's feed read (master.status_view). Two more come with hycosim for
users: :class:`LastValues` (each port's latest value) and :class:`TimeSeries` (chosen ports
over time). A Python caller adds its own with ``Simulation.add_observer``; any object with
these methods will do.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from operator import itemgetter
from pathlib import Path
from typing import Any, Protocol

from hycosim.core.config import LoadedProject
from hycosim.core.schema import Project
from hycosim.core.user_code import import_target

_METHODS = ("step_complete", "state_restored", "run_ended")


class Observer(Protocol):
    """What a run tells an observer (each call in the master's thread: keep it short)."""

    def step_complete(self, step: int, t: float, values: Mapping[str, Any]) -> None:
        """Point ``step`` at ``t`` was recorded with ``values`` (``node.port`` → value, arrays as
        lists; a :class:`RecordedPoint`). The mapping is the master's and changes after the
        call: copy what you keep."""

    def state_restored(self, step: int, t: float) -> None:
        """The run went back to its checkpoint at point ``step``: the points from it on come again."""

    def run_ended(self, status: str) -> None:
        """The run is over: ``status`` as ``meta.json`` says it (completed, stopped, failed, …)."""


class ObserverLoadError(ValueError):
    """An observer the project file names that cannot be made (the message names the entry)."""


def missing_methods(observer: object) -> list[str]:
    """The methods of :class:`Observer` that ``observer`` lacks."""
    return [m for m in _METHODS if not callable(getattr(observer, m, None))]


def project_observers(loaded: LoadedProject) -> list[Observer]:
    """The observers the project file names (``observers``), made; ObserverLoadError naming the
    first that cannot be (its target not there, its constructor failing, a method missing)."""
    base = loaded.path.parent if loaded.path is not None else Path.cwd()
    made = []
    for i, entry in enumerate(loaded.project.observers):
        where = f"observers[{i}]: observer {entry.observer!r}"
        try:
            made.append(import_target(entry.observer, base)(**entry.parameters))
        except Exception as exc:  # the user's code may fail in any way; named, not a traceback
            raise ObserverLoadError(f"{where} cannot be made: {type(exc).__name__}: {exc}") from None
        if missing := missing_methods(made[-1]):
            raise ObserverLoadError(f"{where} is no observer: it lacks {', '.join(missing)}")
    return made


def node_lists(names: Sequence[str]) -> Callable[[Mapping[str, list[Any]]], tuple[list[Any], ...]]:
    """What gives the lists of a point's ``outputs`` or ``inputs`` of nodes ``names``, as a tuple
    in that order: one call in C where there are two nodes or more (itemgetter gives one node's
    list itself, not in a tuple). The recorder and the status answer take each point's values so."""
    names = list(names)
    return itemgetter(*names) if len(names) > 1 else lambda values: tuple(map(values.__getitem__, names))


class RecordedPoint(Mapping[str, Any]):
    """A recorded point as observers see it: its values by ``node.port``, read from the master's
    lists without copying them, and beside the mapping the point whole, for observers that keep
    it as the master holds it (the recorders, the status answer): ``mode``, ``outputs`` and
    ``inputs`` (per node, its ports' values in the project's order), ``stepped`` (a multi-rate
    run's nodes that started a step there), and how the step to it went: ``wait_s`` (from its
    release to the last answer), ``holder`` (the node answering last), ``lateness_s`` (a paced
    run's), ``arrivals`` (each node's answer, seconds after the release), ``ages`` (each
    asynchronous value's), ``takes`` and ``released`` (perf_counter at the release of the step
    from it; None for a point inside a batched release, which had no release of its own).
    One object, its fields replaced at each point: nothing of it outlives the call."""

    __slots__ = ("_where", "mode", "outputs", "inputs", "stepped", "wait_s", "holder", "lateness_s",
                 "arrivals", "ages", "takes", "released")

    def __init__(self, project: Project):
        self._where = {f"{n.nodeName}.{p.name}": ("out", n.nodeName, i)
                       for n in project.nodeLists for i, p in enumerate(n.output)}
        self._where.update({f"{n.nodeName}.{p.name}": ("in", n.nodeName, i)
                            for n in project.nodeLists for i, p in enumerate(n.input)})
        self.mode = ""
        self.outputs: Mapping[str, list[Any]] = {}
        self.inputs: Mapping[str, list[Any]] = {}
        self.stepped: list[str] | None = None
        self.wait_s, self.holder, self.lateness_s = 0.0, "", None
        self.arrivals: dict[str, float] = {}
        self.ages: dict[str, float | None] = {}
        self.takes = 1
        self.released: float | None = None

    def __getitem__(self, port: str) -> Any:
        side, node, i = self._where[port]
        value = (self.outputs if side == "out" else self.inputs)[node][i]
        return list(value) if isinstance(value, list) else value

    def __iter__(self):
        return iter(self._where)

    def __len__(self) -> int:
        return len(self._where)


class LastValues(Observer):
    """Each port's value at the latest point recorded (libcosim's last-value observer)."""

    def __init__(self) -> None:
        self.step: int | None = None
        self.t: float | None = None
        self.values: dict[str, Any] = {}

    def step_complete(self, step: int, t: float, values: Mapping[str, Any]) -> None:
        self.step, self.t, self.values = step, t, dict(values)

    def state_restored(self, step: int, t: float) -> None:
        pass  # the restored point is recorded again next, and replaces these

    def run_ended(self, status: str) -> None:
        pass


class TimeSeries(Observer):
    """Chosen ports at every point recorded: ``t`` and a list per port (libcosim's time-series
    observer). A rollback to a checkpoint drops what lies from its point on."""

    def __init__(self, ports: Iterable[str]):
        self.ports = list(ports)
        self.steps: list[int] = []
        self.t: list[float] = []
        self.values: dict[str, list[Any]] = {p: [] for p in self.ports}

    def step_complete(self, step: int, t: float, values: Mapping[str, Any]) -> None:
        self.steps.append(step)
        self.t.append(t)
        for port in self.ports:
            self.values[port].append(values[port])

    def state_restored(self, step: int, t: float) -> None:
        keep = next((i for i, k in enumerate(self.steps) if k >= step), len(self.steps))
        del self.steps[keep:], self.t[keep:]
        for series in self.values.values():
            del series[keep:]

    def run_ended(self, status: str) -> None:
        pass
