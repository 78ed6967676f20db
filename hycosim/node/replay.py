"""Nodes that play back what a node recorded in an earlier run (``"replay": RUN_DIR``), as
HELICS's Player plays a Recorder's file: a failed trial is run again with its camera (or any
node) exactly as it was, and the others free to change.

A stepping node gives, at each macro-step point, the outputs recorded at that time (at a time
the recording lacks, as an event's localisation tries, those of the last recorded point
before it), and ends the run where the recording ends. An asynchronous node sends each
sample before the macro-step point the recorded server first had it at (the runtime paces it
with the releases, :meth:`SamplePlayer.due`): the same samples are there at every point, so
the values routed from them are the recorded ones, however late the wall clock has them.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from hycosim.core.schema import CoSimulation
from hycosim.core.schema import Node as NodeSpec
from hycosim.core.recordings import Recording, Sample

from hycosim.node.interface import AsyncSource, Node, NodeContext, SimulationEnded, pack_state, unpack_state


class OutputPlayer(Node):
    """A stepping node whose outputs are those a run recorded of it."""

    def __init__(self, source: Path, rows: list[tuple[float, list[Any]]]):
        self._source = source
        self._times = [t for t, _ in rows]
        self._values = [values for _, values in rows]
        self._t = self._times[0]
        self._tol = 0.0

    def setup(self, ctx: NodeContext) -> None:
        self._names = [p.name for p in ctx.outputs]
        self._t = ctx.start_time
        self._tol = 1e-9 * ctx.step_size  # the points' own rounding (origin + j·H)

    def outputs(self) -> dict[str, Any]:
        i = max(bisect_right(self._times, self._t + self._tol) - 1, 0)
        return dict(zip(self._names, self._values[i]))

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        end = self._times[-1]
        if t + h > end + self._tol:
            raise SimulationEnded(end, f"its recording in {self._source} ends at t={end:g} s")
        self._t = t + h

    @property
    def can_rollback(self) -> bool:
        return True

    def get_state(self) -> bytes:
        return pack_state({"t": self._t})

    def set_state(self, state: Any) -> None:
        t = unpack_state(state, {"t"})["t"]
        if type(t) is not float:
            raise ValueError("a state whose time is not a float")
        self._t = t


class SamplePlayer(AsyncSource):
    """An asynchronous node whose samples are those a run received from it."""

    def __init__(self, samples: list[Sample]):
        self._samples = samples
        self._points = [s.point for s in samples]
        self._names: list[str] = []
        self._next = 0  # for samples_until: by time stamp alone

    def setup(self, ctx: NodeContext) -> None:
        self._names = [p.name for p in ctx.outputs]

    def values(self, sample: Sample) -> dict[str, Any]:
        """A recorded sample's values by output name."""
        return dict(zip(self._names, sample.values))

    def due(self, after: int, upto: int) -> list[Sample]:
        """The samples the recorded server first had at points ``after`` < point <= ``upto``, in
        the order it received them."""
        return self._samples[bisect_right(self._points, after):bisect_right(self._points, upto)]

    def samples_until(self, t: float) -> Iterator[tuple[float, dict[str, Any]]]:
        # Unpaced (by the clock alone): each sample when the run reaches its time stamp.
        while self._next < len(self._samples) and self._samples[self._next].t <= t:
            sample = self._samples[self._next]
            self._next += 1
            yield sample.t, self.values(sample)


def player(spec: NodeSpec, project_dir: Path, cosim: CoSimulation) -> OutputPlayer | SamplePlayer:
    """The node that plays the recording ``spec``'s ``replay`` names (relative to the project's
    folder), read whole; RecordingError if it does not fit the node or the run's steps."""
    recording = Recording((project_dir / str(spec.replay)).resolve())
    recording.require_fit(spec, cosim)
    if spec.asynchronous:
        return SamplePlayer(recording.samples(spec))
    return OutputPlayer(recording.run_dir, recording.outputs(spec))
