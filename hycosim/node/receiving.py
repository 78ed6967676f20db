"""What a node takes from the server: the next frame within a bound, the server's liveliness
(a link cut waited out within linkGrace), and every frame checked before the node acts on it
(a release's inputs against the node's ports, a state's pieces, steps and times in range)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from typing import Any

from hycosim.core import frames
from hycosim.core.drops import DropLog
from hycosim.core.schema import WIRE_TYPES, CoSimulation, Node as NodeSpec, wire_types
from hycosim.node.releases import ReleaseReader
from hycosim.transport.inbox import LOCAL
from hycosim.transport.node_side import NodeLink


class NodeRunError(RuntimeError):
    """The node cannot go on; the message names the node and the step."""


class Receiver:
    """Frames for node ``name`` from its link. ``steps`` tells the node's last step (for the
    messages); ``interpolating``: whether its releases may carry input slopes."""

    def __init__(self, spec: NodeSpec, cosim: CoSimulation, endpoint: str, drops: DropLog, log: Any,
                 steps: Callable[[], int], drives: Mapping[str, tuple[str, ...]]):
        self.name, self.cosim, self.endpoint, self.drops, self.log, self.steps = (
            spec.nodeName, cosim, endpoint, drops, log, steps)
        # Releases carry inputs for the stepping nodes; an asynchronous source only reads their time.
        self.release_for = None if spec.asynchronous else spec.nodeName
        self.in_types = tuple(wire_types(p) for p in spec.input)
        self.in_arrays = tuple((i, p.size, WIRE_TYPES[p.type]) for i, p in enumerate(spec.input)
                               if p.shape is not None)
        self.interpolating = False
        # A stepping node reads a release's own entry alone (node/releases.py); its releases
        # over Zenoh take the flat path (ReleaseReader.plain in ZenohNode) where every input is a
        # scalar (``flat``); otherwise every release goes the whole way. ``drives``: each mode's
        # driven nodes, as its releases name them.
        self.releases = ReleaseReader(self.release_for, self.in_types, drives) \
            if self.release_for is not None else None
        self._decode = self.releases.decode if self.releases is not None else frames.decode
        self.flat = self.releases is not None and self.releases.flat
        self.tunable: dict[str, Any] = {}  # the model's tunable parameters and their start values
        self.link: NodeLink | None = None
        self.pulls = False  # over Zenoh frames are pulled; in process the master pushes them
        self.server_lost: float | None = None
        self.server_seen = False  # its liveliness token, which tells this node when it goes

    def wait(self, timeout: float, what: str) -> frames.Frame:
        """The next frame from the server (skipping ones not for us); STOP ends the wait too."""
        frame = self.next_frame(timeout)
        if frame is None:
            raise self.silence(timeout, what)
        return frame

    def silence(self, timeout: float, what: str) -> NodeRunError:
        """The error for no ``what`` from the server within ``timeout`` seconds."""
        return NodeRunError(f"node {self.name!r}: no {what} from the server at {self.endpoint} "
                            f"within {timeout:g} s (after step {self.steps()})")

    def next_frame(self, timeout: float) -> frames.Frame | None:
        """The next frame from the server within ``timeout`` seconds, or None.

        Liveliness is handled here: if the server's token goes (a link cut), wait up to
        linkGrace for it to come back, then stop. Malformed frames are dropped.
        """
        if not self.pulls:
            return None  # in process the master pushes its frames: nothing comes by waiting
        deadline = time.monotonic() + timeout
        grace = self.cosim.linkGrace
        while True:
            now = time.monotonic()
            wait = deadline - now
            if self.server_lost is not None:
                if now - self.server_lost > grace:
                    raise NodeRunError(f"node {self.name!r}: the server went away after step {self.steps()} and "
                                       f"did not come back within the link grace of {grace:g} s")
                wait = min(wait, self.server_lost + grace - now + 0.01)
            msg = self.link.receive(max(wait, 0.0))
            if msg is None:
                if time.monotonic() < deadline:
                    continue  # woken for the grace check above
                return None
            frame = self.take(msg)
            if frame is not None:
                return frame

    def take(self, msg: tuple[str, bytes]) -> frames.Frame | None:
        """One message of the link: a frame to act on, or None for one dropped (counted), one
        for another node, or the server's liveliness news (taken in here: a link cut is waited
        out by :meth:`next_frame` within linkGrace; without a grace it ends the node)."""
        try:
            key, payload = msg
            frame = self.accept(key == LOCAL, payload)
        except frames.FrameError as exc:
            self.drops.drop("not a release", str(exc), self.steps())
            return None
        if frame is None or frame.kind != frames.LIVE:
            return frame
        if frame.alive:
            self.log.info("server back" if self.server_seen else "server seen", step=self.steps())
            self.server_lost, self.server_seen = None, True
        elif self.cosim.linkGrace > 0:
            self.server_lost = time.monotonic()
            self.log.warning("server lost, waiting for it", step=self.steps(), grace_s=self.cosim.linkGrace)
        else:
            raise NodeRunError(f"node {self.name!r}: the server went away after step {self.steps()}")
        return None

    def accept(self, local: bool, payload: bytes) -> frames.Frame | None:
        """A frame from ``down`` (or this process's own liveliness news) that this node can act
        on; None for one meant for another node; FrameError for anything else."""
        return self.accept_frame(local, self._decode(payload))

    def accept_frame(self, local: bool, frame: frames.Frame) -> frames.Frame | None:
        """:meth:`accept` of a frame decoded already."""
        kind = frame.kind
        if local:
            return frame  # liveliness news from this process's own subscriber
        if kind in (frames.STEP, frames.STEPS) and self.release_for is not None and \
                self.release_for not in frame.inputs:
            return None  # a release of other nodes (this one is not due, or not yet in Gauss-Seidel order)
        if kind in (frames.START, frames.STEP, frames.STEPS):
            return frames.check_release(frame, self.release_for, self.in_types, self.interpolating, self.in_arrays)
        if kind == frames.INIT:
            if self.name not in frame.inputs:
                return None  # the initialisation of other nodes
            return frames.check_release(frame, self.name, self.in_types, input_arrays=self.in_arrays)
        if kind == frames.REPLAY:
            if frame.node != self.name:
                return None
            inner = self._decode(frame.release)
            if inner.kind not in (frames.START, frames.STEP, frames.STEPS):
                raise frames.FrameError(f"a replay of a {frames.KIND_NAMES[inner.kind]} frame")
            return frames.Replay(self.name, frames.check_release(inner, self.release_for, self.in_types,
                                                              self.interpolating, self.in_arrays))
        if kind == frames.ROLLBACK:
            k, t = frame.step, frame.t
            if not (0 <= k < frames.MAX_STEP and math.isfinite(t)):
                raise frames.FrameError(f"ROLLBACK frame to step {k}, t {t}: out of range")
            return frame
        if kind == frames.STOP:
            return frame
        if kind == frames.TUNE:
            if frame.node != self.name:
                return None
            return frames.check_tune(frame, self.name, self.tunable)
        if kind == frames.CHECKPOINT:
            if not 0 <= frame.step < frames.MAX_STEP:
                raise frames.FrameError(f"CHECKPOINT frame at step {frame.step}: out of range")
            return frame
        if kind == frames.RESTORE:
            if frame.node != self.name:
                return None
            frames.check_chunk(frame.step, frame.index, frame.count, frame.chunk)
            if not math.isfinite(frame.t):
                raise frames.FrameError(f"RESTORE frame to t {frame.t}: not finite")
            return frame
        raise frames.FrameError(f"a {frames.KIND_NAMES[kind]} frame is not for a node")
