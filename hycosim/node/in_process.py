"""A node hosted in process: its master in the same process pushes each frame to
:meth:`HostedNode.deliver`, and, where the run's plan allows, steps it by a call
(:meth:`HostedNode.step_direct`) instead of a frame."""

from __future__ import annotations

from typing import Any, Callable

from hycosim.core import frames
from hycosim.node.interface import AsyncSource
from hycosim.node.receiving import NodeRunError
from hycosim.node.replay import SamplePlayer
from hycosim.node.runtime import NodeRuntime
from hycosim.transport.local_bus import LocalBus
from hycosim.transport.node_side import LocalNodeLink


class HostedNode(NodeRuntime):
    """One node of an in-process run: :meth:`host` attaches it to the run's bus."""

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self._listed: Callable[[float, float, list[Any]], list[Any]] | None = None  # Node.listed_step

    def host(self, bus: LocalBus) -> None:
        """Set the model up and attach this node to an in-process run (its master in this
        process): from now on :meth:`deliver` acts on each frame the master releases, in the
        master's thread. A stepping node or a played recording; an asynchronous source keeps
        its own clock and is run distributed."""
        if isinstance(self.impl, AsyncSource) and not isinstance(self.impl, SamplePlayer):
            raise NodeRunError(f"node {self.name!r}: an asynchronous source samples on its own clock beside the "
                               "run, which one process stepping every node cannot give it; run it without "
                               "--in-process")
        self._setup()
        self.receiver.link = LocalNodeLink(bus, self.name)
        if not self._is_player:
            # An FMU steps on the master's lists as they are (no dicts between, no conversions).
            self._listed = self.impl.listed_step(list(self._in_names), list(self.spec.output))
        bus.attach(self.name, self.deliver, None if self._is_player else self.step_direct)

    def step_direct(self, k: int, t: float, h: float, mode: str, driven: bool, inputs: list[Any]) -> list[Any] | None:
        """The release of step k (t → t + h) to this node in process, as a call: what a STEP frame
        does, on ``inputs`` (the master's routing of outputs it checked; no network between).
        Return the outputs at t + h, checked as those sent are; None when the model ended the
        run or failed instead, its END sent to the master as over the network."""
        impl, at = self.impl, self._stepping  # a Node (host attaches no player this way), started
        if self.failure is not None:
            return None  # it failed taking a frame (a TUNE): its END is with the master
        try:
            self._enter_step(impl, at, k, mode, driven)
            if self._listed is not None:  # the values go into the FMU's own buffers
                out = self._listed(t, h, inputs)
            else:
                values = dict(zip(self._in_names, inputs))
                for i, _, _ in self.receiver.in_arrays:  # the master's lists stay its own, whatever the model does
                    name = self._in_names[i]
                    values[name] = list(values[name])
                impl.step(t, h, values)
                out = self.outbox.pack(impl.outputs())
        except Exception as exc:
            try:
                self._step_failed(exc, k, t, impl=impl)
            except NodeRunError as failure:
                self.failure = str(failure)
            self.link.close()
            return None
        self.steps, at.done = k + 1, k
        return out

    def deliver(self, frame: frames.Frame) -> None:
        """Act on one frame the in-process master released, checked as one from the network is.
        A node that fails sends its END (the master stops the run with its words), keeps the
        message in :attr:`failure` and takes no more frames."""
        try:
            frame = self.receiver.accept_frame(False, frame)
        except frames.FrameError as exc:
            self.drops.drop("not a release", str(exc), self.steps)
            return
        if frame is None:
            return
        try:
            done = self.handle(frame)
        except NodeRunError as exc:
            self.failure, done = str(exc), True
        if done:
            self.link.close()

    def close(self) -> None:
        """An in-process node's end: its model's teardown (a Zenoh node's run does its own)."""
        self.impl.teardown()
