"""The node runtime: attach one node to a run and step it until STOP.

Every frame the master releases goes through one handler, :meth:`NodeRuntime.handle`,
whatever transport carried it (``hycosim.transport.node_side``): over Zenoh :meth:`run`
pulls the frames from its link and feeds them to it, with the link grace and every wait
bounded; in process (:meth:`host`) the master pushes them by calling :meth:`deliver`. An
asynchronous source samples on its own clock and runs over Zenoh only.
"""

from __future__ import annotations

import math
import signal
import socket
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import structlog

from hycosim.core import frames, signals
from hycosim.core.schema import WIRE_TYPES, Port, PortType, wire_types
from hycosim.core.config import LoadedProject
from hycosim.core.drops import DropLog
from hycosim.transport.inbox import LOCAL
from hycosim.transport.local_bus import LocalBus
from hycosim.transport.node_side import LocalNodeLink, NodeLink, ZenohNodeLink
from hycosim.transport.session import FrameTooLarge
from hycosim.core.sim_clock import RealTimeClock

from hycosim.node.interface import AsyncSource, Node, NodeContext, NodeModelError, SimulationEnded
from hycosim.node.replay import SamplePlayer

_COERCE = {
    PortType.REAL: float,
    PortType.INTEGER: int,
    PortType.BOOLEAN: bool,
    PortType.STRING: str,
    PortType.BINARY: bytes,
}


def _coerce(port: Port) -> Callable[[Any], Any]:
    """How a model's value for ``port`` becomes its wire value: an array's, element by element,
    into a list of its shape's size (ValueError otherwise)."""
    one = _COERCE[port.type]
    if port.shape is None:
        return one
    import numpy  # only for array ports: a scalar Python node starts without it (a tenth of a second)

    size = port.size

    def array(value: Any) -> list[Any]:
        if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
            raise ValueError(f"{type(value).__name__} {str(value)[:40]!r} for array port {port.name!r} "
                             f"of shape {list(port.shape)}")
        # numpy flattens row-major whatever the model gives: a numpy array, a list, nested lists.
        flat = numpy.asarray(value).ravel().tolist()
        if len(flat) != size:
            raise ValueError(f"{len(flat)} values for array port {port.name!r} of shape {list(port.shape)} "
                             f"({size} elements)")
        return [one(x) for x in flat]
    return array


# How long a node a supervisor stops (SIGTERM, SIGHUP) waits for the server to read its END:
# well inside the 10 s a supervisor (docker, systemd) gives before it kills.
_STOPPED_WAIT = 2.0

# The releases of a step, the frames a stepping node acts on at every point.
_STEP_KINDS = frozenset((frames.STEP, frames.STEPS))


class NodeRunError(RuntimeError):
    """The node cannot go on; the message names the node and the step."""


class RunFailedElsewhere(NodeRunError):
    """The server stopped a run that failed (another node lost, a timeout): this node's end too."""


class NodeRuntime:
    def __init__(self, loaded: LoadedProject, node_name: str, impl: Node | AsyncSource, endpoint: str,
                 password: str | None = None):
        self.loaded = loaded
        self.spec = loaded.project.node(node_name)
        self.name = node_name
        self.impl = impl
        self.endpoint = endpoint
        self.password = password
        self.cosim = loaded.project.coSimulation
        self._out_ports = [(p.name, _coerce(p)) for p in self.spec.output]
        self._in_names = self.spec.input_names()
        self._in_types = tuple(wire_types(p) for p in self.spec.input)
        self._in_arrays = tuple((i, p.size, WIRE_TYPES[p.type]) for i, p in enumerate(self.spec.input)
                                if p.shape is not None)
        # Releases carry inputs for the stepping nodes; an asynchronous source only reads their time.
        self._release_for = None if self.spec.asynchronous else node_name
        # Multi-rate: this node steps over this many base steps, at every such base point.
        self._rate = loaded.coupling.rates.get(node_name, 1)
        self._log = structlog.get_logger("node").bind(node=node_name)
        self.drops = DropLog(self._log)
        self.steps = 0
        self.samples = 0  # an asynchronous source's samples sent
        self._server_lost: float | None = None
        self._server_seen = False  # its liveliness token, which tells this node when it goes
        # Where frames go and come from (run: Zenoh; host: the in-process bus). Over Zenoh
        # the handler's acknowledgements (a STOP after an END) are waited for; in process the
        # master reads what a node sent as soon as its call returns.
        self.link: NodeLink | None = None
        self._pulls = False
        self._phase = _START  # what the next frame is taken as (see handle)
        self._returning = False  # a START again after a link cut, or the run's, to a restarted process
        self._restoring: _Restoring | None = None
        self._restart_deadline = 0.0
        self._restoring_step = -1  # the step the run was at when a restarted process attached
        self._stepping: _Stepping | None = None
        self._interpolating = self._is_player = False  # set once the model is set up
        self._played: _Played | None = None
        self.failure: str | None = None  # in process: why this node ended the run, if it failed
        self._listed: Callable[[float, float, list[Any]], list[Any]] | None = None  # in process: Node.listed_step

    def context(self) -> NodeContext:
        params = dict(self.spec.parameters)
        if self.spec.rate is not None:
            params.setdefault("rate", self.spec.rate)
        project_dir = self.loaded.path.parent if self.loaded.path else None
        return NodeContext(self.name, self.spec.UID, list(self.spec.input), list(self.spec.output), params,
                           self.cosim.stepSize, self.cosim.startTime, **({"project_dir": project_dir} if project_dir else {}),
                           real_time=self.cosim.real_time_factor(), stop_time=self.cosim.stopTime)

    def _pack_outputs(self, values: dict[str, Any]) -> list[Any]:
        packed = []
        for port, coerce in self._out_ports:
            if port not in values:
                raise NodeRunError(f"node {self.name!r}: its model returned no value for output {port!r}")
            try:
                packed.append(coerce(values[port]))
            except (TypeError, ValueError, OverflowError) as exc:
                raise NodeRunError(f"node {self.name!r}: output {port!r}: {exc}") from None
        return packed

    def _setup(self) -> None:
        try:
            self.impl.setup(self.context())
            # Asked of every release a node checks: what it is does not change once set up.
            self._interpolating = isinstance(self.impl, Node) and self.impl.can_interpolate
            self._is_player = isinstance(self.impl, SamplePlayer)
        except Exception as exc:
            if isinstance(exc, NodeRunError):
                raise
            if isinstance(exc, NodeModelError):  # a clear message of its own
                raise NodeRunError(str(exc)) from None
            raise NodeRunError(f"node {self.name!r}: its model failed to set up: {type(exc).__name__}: {exc}") from exc

    def run(self) -> None:
        """Attach to the server over Zenoh and take part in the run until its STOP."""
        self._setup()
        try:
            link = ZenohNodeLink.open(self.loaded, self.name, self.endpoint, self.password)
            self.link, self._pulls = link, True
            try:
                if isinstance(self.impl, AsyncSource) and not isinstance(self.impl, SamplePlayer):
                    start = self._source_start()
                    if start.kind == frames.STOP:
                        self._on_stop(start)
                    else:
                        self._run_async(start, self._returning)
                    return
                while not self.handle(self._pull()):
                    pass
            except KeyboardInterrupt as exc:
                self._say_stopped(exc)
                raise
            finally:
                link.close()
        finally:
            try:
                self.impl.teardown()
            finally:
                if self.link is not None:
                    self.link.session.close()

    def _pull(self) -> frames.Frame:
        """The next frame over Zenoh, within what the phase the node is in allows."""
        if self._phase == _START:
            # The server times out the attach; outwait it so that its STOP, naming who is
            # missing, reaches this node rather than a timeout of our own.
            try:
                return self._wait(self.cosim.attachTimeout + self.cosim.stepTimeout, "START")
            except NodeRunError as exc:
                raise NodeRunError(f"{exc}{self.link.other_projects()}") from None
        if self._phase == _RESTART:
            frame = self._next_frame(max(0.0, self._restart_deadline - time.monotonic()))
            if frame is None:
                wait = self.cosim.attachTimeout + self.cosim.stepTimeout
                raise NodeRunError(f"node {self.name!r}: the run on {self.endpoint} was already under way "
                                   f"(step {self._restoring_step}) when it attached, and the server did not restore "
                                   f"it within {wait:g} s: a node restarted mid-run goes on only from a checkpoint "
                                   "(coSimulation.checkpointEvery)")
            return frame
        if self._phase == _RESTORING:
            frame = self._next_frame(self.cosim.stepTimeout)
            if frame is None:
                return self._restore_cut_short()
            return frame
        # The server enforces step timeouts; a node only needs to notice the server is gone,
        # which liveliness tells; this bound is the last resort for a frozen server.
        return self._wait(self.cosim.stepTimeout + 30.0, "release")

    def _source_start(self) -> frames.Frame:
        """An asynchronous source's START (a restarted one's too: a source has no state to restore)."""
        start = self._wait(self.cosim.attachTimeout + self.cosim.stepTimeout, "START")
        if start.kind == frames.REPLAY:
            self._returning, start = True, start.release
        if start.kind not in (frames.START, frames.STOP):
            at = f" (step {start.step})" if start.kind in (frames.STEP, frames.STEPS) else ""
            raise NodeRunError(f"node {self.name!r}: the run on {self.endpoint} was already under way{at} "
                               "when it attached; a node joins before the run starts")
        return start

    def handle(self, frame: frames.Frame) -> bool:
        """Act on one frame the master released to this node, accepted already (checked as every
        receiver checks, and meant for it); True once the node is done: the run's STOP, or its
        model ended the simulation. Every transport's frames come here."""
        if self._phase == _STEPPING:
            return self._on_release(frame)
        if self._phase == _PLAYED:
            return self._on_played(frame)
        if self._phase == _START:
            return self._on_start(frame)
        if frame.kind == frames.STOP:  # restarting or restoring: the run ended instead
            self._on_stop(frame)
            return True
        if self._phase == _RESTART:
            return self._begin_restore(frame) if frame.kind == frames.RESTORE else False
        return self._on_restore_piece(frame)

    def _on_start(self, frame: frames.Frame) -> bool:
        """The first frame of the run: its START (HELLO and the outputs at t0), or, to a process
        that replaces one that died, the run's last release (say so, and wait to be restored)
        or the first piece of a state to restore."""
        if frame.kind == frames.REPLAY:
            # START again after a link cut during the attach; or, to a process that replaces
            # one that died, the run's START (a player) or last release.
            self._returning, frame = True, frame.release
        if frame.kind == frames.STOP:
            self._on_stop(frame)
            return True
        if isinstance(self.impl, SamplePlayer):
            self._begin_played(frame, self._returning)
            self._phase = _PLAYED
            return self._on_played(frame)
        if frame.kind in _STEP_KINDS:
            # The run is under way: this process is a restart. Say so at once (a node process
            # says HELLO once per run); a server that takes checkpoints restores the run, and
            # this node with it; one that does not stops the run.
            self._send(self._hello(False, restart=True))
            self._log.info("restarted: waiting for the run to be restored", step=frame.step)
            self._restoring_step = frame.step
            self._restart_deadline = time.monotonic() + self.cosim.attachTimeout + self.cosim.stepTimeout
            self._phase = _RESTART
            return False
        if frame.kind == frames.RESTORE:
            return self._begin_restore(frame)
        if frame.kind != frames.START:
            raise NodeRunError(f"node {self.name!r}: the run on {self.endpoint} was already under way "
                               "when it attached; a node joins before the run starts")
        self._phase = _STEPPING
        return not self._begin_stepping(bool(frame.options.get("checkpoint")))

    def _send(self, payload: bytes) -> None:
        """Publish one frame; one too large for the link stops the node, naming its largest outputs."""
        try:
            self.link.send(payload)
        except FrameTooLarge as exc:
            frame = frames.decode(payload)
            values = frame.values if frame.kind in (frames.OUTPUTS, frames.SAMPLE, frames.BATCH) else []
            largest = frames.largest_values(zip((port for port, _ in self._out_ports), values))
            raise NodeRunError(f"node {self.name!r}: its outputs at step {self.steps} are {exc}; "
                               f"largest: {largest}") from None

    def _send_outputs(self, payload: bytes, step: int) -> None:
        """Send outputs and count them as this node's last ``step`` with no stop signal between:
        a SIGTERM that came after the send and before the count had the node's END name the
        step before the one the server had (once, in a loaded make test)."""
        signals.hold_stops()
        try:
            self._send(payload)
            self.steps = step
        finally:
            signals.release_stops()

    def _wait(self, timeout: float, what: str) -> frames.Frame:
        """The next frame from the server (skipping ones not for us); STOP ends the wait too."""
        frame = self._next_frame(timeout)
        if frame is None:
            raise NodeRunError(f"node {self.name!r}: no {what} from the server at {self.endpoint} "
                               f"within {timeout:g} s (after step {self.steps})")
        return frame

    def _next_frame(self, timeout: float) -> frames.Frame | None:
        """The next frame from the server within ``timeout`` seconds, or None.

        Liveliness is handled here: if the server's token goes (a link cut), wait up to
        linkGrace for it to come back, then stop. Malformed frames are dropped.
        """
        if not self._pulls:
            return None  # in process the master pushes its frames: nothing comes by waiting
        deadline = time.monotonic() + timeout
        grace = self.cosim.linkGrace
        while True:
            now = time.monotonic()
            wait = deadline - now
            if self._server_lost is not None:
                if now - self._server_lost > grace:
                    raise NodeRunError(f"node {self.name!r}: the server went away after step {self.steps} and did not "
                                       f"come back within the link grace of {grace:g} s")
                wait = min(wait, self._server_lost + grace - now + 0.01)
            msg = self.link.receive(max(wait, 0.0))
            if msg is None:
                if time.monotonic() < deadline:
                    continue  # woken for the grace check above
                return None
            try:
                frame = self._accept(msg[0] == LOCAL, msg[1])
            except frames.FrameError as exc:
                self.drops.drop("not a release", str(exc), self.steps)
                continue
            if frame is None:
                continue
            if frame.kind == frames.LIVE:
                if frame.alive:
                    self._log.info("server back" if self._server_seen else "server seen", step=self.steps)
                    self._server_lost, self._server_seen = None, True
                elif grace > 0:
                    self._server_lost = time.monotonic()
                    self._log.warning("server lost, waiting for it", step=self.steps, grace_s=grace)
                else:
                    raise NodeRunError(f"node {self.name!r}: the server went away after step {self.steps}")
                continue
            return frame

    def _accept(self, local: bool, payload: bytes) -> frames.Frame | None:
        """A frame from ``down`` (or this process's own liveliness news) that this node can act
        on; None for one meant for another node; FrameError for anything else."""
        return self._accept_frame(local, frames.decode(payload))

    def _accept_frame(self, local: bool, frame: frames.Frame) -> frames.Frame | None:
        """:meth:`_accept` of a frame decoded already."""
        kind = frame.kind
        if local:
            return frame  # liveliness news from this process's own subscriber
        if kind in (frames.STEP, frames.STEPS) and self._release_for is not None and \
                self._release_for not in frame.inputs:
            return None  # a release of other nodes (this one is not due, or not yet in Gauss-Seidel order)
        if kind in (frames.START, frames.STEP, frames.STEPS):
            return frames.check_release(frame, self._release_for, self._in_types, self._interpolating,
                                        self._in_arrays)
        if kind == frames.INIT:
            if self.name not in frame.inputs:
                return None  # the initialisation of other nodes
            return frames.check_release(frame, self.name, self._in_types, input_arrays=self._in_arrays)
        if kind == frames.REPLAY:
            if frame.node != self.name:
                return None
            inner = frames.decode(frame.release)
            if inner.kind not in (frames.START, frames.STEP, frames.STEPS):
                raise frames.FrameError(f"a replay of a {frames.KIND_NAMES[inner.kind]} frame")
            return frames.Replay(self.name, frames.check_release(inner, self._release_for, self._in_types,
                                                              self._interpolating, self._in_arrays))
        if kind == frames.ROLLBACK:
            k, t = frame.step, frame.t
            if not (0 <= k < frames.MAX_STEP and math.isfinite(t)):
                raise frames.FrameError(f"ROLLBACK frame to step {k}, t {t}: out of range")
            return frame
        if kind == frames.STOP:
            return frame
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

    def _say_stopped(self, exc: BaseException) -> None:
        """A node stopped by SIGTERM or SIGHUP (its supervisor) tells the server, which then names it
        rather than a lost token. Not on Ctrl-C: a terminal's reaches the server too, which
        reports its own interruption."""
        if signals.signal_of(exc) == signal.SIGINT:
            return
        # A source knows no step (the server adds the run's).
        said = (f"node {self.name!r} (an asynchronous source) {signals.describe(exc)}"
                if isinstance(self.impl, AsyncSource) else
                f"node {self.name!r} {signals.describe(exc)} after step {self.steps}")
        try:
            self._send(frames.encode(frames.END, self.spec.UID, self.steps + 1, 0.0, False, said, [], None))
            # The token goes as this process leaves, and the server can learn that before it
            # reads the END (it did on a loaded machine, and named a lost token): wait for its
            # STOP, which says it has read it. A second signal ends the wait.
            deadline = time.monotonic() + _STOPPED_WAIT
            while (left := deadline - time.monotonic()) > 0:
                frame = self._next_frame(left)
                if frame is None or frame.kind == frames.STOP:
                    break
        except Exception:  # on its way out: the token's loss still tells the server
            pass

    def _end(self, step: int, t: float, clean: bool, message: str, earlier: list[list[Any]] | None = None,
             last: list[Any] | None = None) -> None:
        """Tell the server this node's model ended the run (``clean``) or failed, in place of its
        outputs for ``step`` (``earlier``: those of its steps inside a batch before that;
        ``last``: its outputs at ``t``, where the model ended, if it could give them), and
        wait for the server's STOP (so that it hears this first, not that the node's token
        went). A failure is raised as this node's own."""
        message = message[:2000]
        try:
            self._send(frames.encode(frames.END, self.spec.UID, step, t, clean, message, earlier or [], last))
            # In process the master reads the END once this call returns: there is nothing to wait for.
            deadline = time.monotonic() + (min(10.0, self.cosim.stepTimeout) if self._pulls else 0.0)
            while (left := deadline - time.monotonic()) > 0:
                frame = self._next_frame(left)
                if frame is None or frame.kind == frames.STOP:
                    break
        except NodeRunError:
            pass  # the server is gone: the node's own message says enough
        if not clean:
            raise NodeRunError(message)
        self._log.info("ended the simulation", step=step, t=t, message=message)

    def _step_model(self, impl: Node, k: int, t: float, h: float | None, inputs: dict[str, Any]) -> bytes | None:
        """Step the model from t by h (h None: only read its outputs at t, k = -1), send its
        outputs at step k + 1 and return them as sent; None if it ended the simulation. A model
        that fails, or whose outputs cannot be sent, is reported to the server (END) and raised."""
        try:
            if h is not None:
                impl.step(t, h, inputs)
            frame = frames.encode(frames.OUTPUTS, self.spec.UID, k + 1, t + (h or 0.0),
                                  self._pack_outputs(impl.outputs()))
            self._send_outputs(frame, k + 1)
            return frame
        except Exception as exc:
            self._step_failed(exc, k, t, impl=impl)
            return None  # the model ended the simulation (_step_failed raises for a failure)

    def _step_failed(self, exc: Exception, k: int, t: float, earlier: list[list[Any]] | None = None,
                     impl: Node | None = None) -> None:
        """Tell the server, in place of the outputs of the release at point k (from t), how the
        model's step ended: a model that ended the simulation returns (with ``earlier``, the
        outputs of its steps before inside a batch, and its outputs where it ended); a failure
        is raised."""
        if isinstance(exc, SimulationEnded):
            self._end(k + 1, exc.t, True, f"{exc}", earlier, self._outputs_at_end(impl))
        elif isinstance(exc, NodeRunError):
            self._end(k + 1, t, False, str(exc))
        elif isinstance(exc, NodeModelError):
            self._end(k + 1, t, False, f"{exc} (step {k})")
        else:
            self._log.exception("model failed", step=k)
            self._end(k + 1, t, False, f"node {self.name!r}: its model failed at step {k} (t={t:g} s): "
                                       f"{type(exc).__name__}: {exc}")

    def _outputs_at_end(self, impl: Node | None) -> list[Any] | None:
        """The outputs of a model that ended the simulation, at the time it ended (FMPy records
        them there too: an FMU may be asked for its values after it discarded a step), or None
        where the model cannot give them."""
        if impl is None:
            return None
        try:
            return self._pack_outputs(impl.outputs())
        except Exception as exc:  # noqa: BLE001 - a model that ended may refuse; the END still goes
            self._log.info("no outputs where the model ended", error=f"{type(exc).__name__}: {exc}")
            return None

    def _step_batch(self, impl: Node, k: int, times: list[float], inputs: dict[str, Any]) -> bytes | None:
        """A batched release (STEPS) from point k over the base points ``times``: this node's own
        steps that start inside it, each as a STEP would have it (a base-rate node from one
        point to the next, a slower one over its rate, cut at stopTime), all on ``inputs``;
        send the outputs after each as one BATCH labelled k + 1 and return it. None if the
        model ended the simulation; a failure is reported (END) and raised."""
        outs: list[list[Any]] = []
        t = end = times[0]
        try:
            for i in range(0, len(times) - 1, self._rate):
                t = times[i]
                end = times[i + 1] if self._rate == 1 else t + min(self._rate * self.cosim.stepSize,
                                                                    self.cosim.stopTime - t)
                impl.step(t, end - t, inputs)
                outs.append(self._pack_outputs(impl.outputs()))
            frame = frames.encode(frames.BATCH, self.spec.UID, k + 1, end, outs[-1], outs[:-1])
            self._send_outputs(frame, k + len(times) - 1)
            return frame
        except Exception as exc:
            self._step_failed(exc, k, t, outs, impl=impl)
            return None  # the model ended the simulation (_step_failed raises for a failure)

    def _begin_restore(self, frame: frames.Frame) -> bool:
        """The first piece of a state to restore, to a process that joins a run under way or to
        one the run's server resumes: the node steps once it is set (see :meth:`_on_restore_piece`)."""
        self._stepping = _Stepping(bool(frame.options.get("checkpoint")) and self.impl.can_rollback)
        self._restoring, self._phase = _Restoring(first_of_run=True), _RESTORING
        return self._on_restore_piece(frame)

    def _on_restore_piece(self, frame: frames.Frame) -> bool:
        """One piece of the state the server restores (the whole run went back to a checkpoint):
        once all are in, set it, answer with a HELLO and the outputs at the checkpoint's point,
        and step from there. True if the model ended the simulation there."""
        at, impl = self._restoring, self.impl
        if frame.kind != frames.RESTORE:
            self.drops.drop("not a release", f"the state to restore at step {at.step} came in part", self.steps)
            return self._restore_failed()
        at.step, at.t = frame.step, frame.t
        data = at.chunks.add(frame.step, frame.index, frame.count, frame.chunk)
        if data is None:
            return False
        try:
            impl.deserialize_state(data)
        except Exception as exc:  # a state from another build of the model, or a forged frame
            self.drops.drop("not a release", f"a state to restore at step {at.step} that does not fit: "
                            f"{type(exc).__name__}: {exc}", self.steps)
            return self._restore_failed()
        self._log.info("restored", step=at.step, t=at.t)
        self._restoring, self._phase = None, _STEPPING
        self._send(self._hello(impl.can_rollback))
        out = self._step_model(impl, at.step - 1, at.t, None, {})
        if out is None:
            return True
        st = self._stepping
        st.last_out, self.steps, st.done = out, at.step, at.step - 1
        if not at.first_of_run:  # this node's saved states are of the future
            st.mode, st.saved_step, st.pending_state = None, -1, None
        return False

    def _restore_failed(self) -> bool:
        """A state to restore that came in part or does not fit (the frame is dropped): a node
        that has nothing else to step from stops; one under way goes on as it was."""
        first, self._restoring, self._phase = self._restoring.first_of_run, None, _STEPPING
        if first:
            raise NodeRunError(f"node {self.name!r}: the state the server sent to restore could not be set "
                               f"(see {self.name}'s log)")
        return False

    def _restore_cut_short(self) -> frames.Frame:
        """No next piece of a state within the step timeout: as a piece that is not one."""
        self.drops.drop("not a release", f"the state to restore at step {self._restoring.step} came in part",
                        self.steps)
        self._restore_failed()
        return self._pull()

    def _begin_stepping(self, checkpoint: bool) -> bool:
        """Answer the START: HELLO and the outputs at t0; False if the model ended the simulation there."""
        impl = self.impl
        assert isinstance(impl, Node)
        at = self._stepping = _Stepping(checkpoint and impl.can_rollback)
        self._send(self._hello(impl.can_rollback))
        out = self._step_model(impl, -1, self.cosim.startTime, None, {})
        if out is None:
            return False
        at.last_out = out
        return True

    def _on_release(self, frame: frames.Frame) -> bool:
        """Act on one frame from the server while stepping; True once this node is done (the
        run's STOP, or its model ended the simulation)."""
        if frame.kind not in _STEP_KINDS:  # the run's control: checked after the releases, which come each step
            done, frame = self._on_control(frame)
            if frame is None:
                return done
        impl, at = self.impl, self._stepping  # a Node: only a stepping node has _stepping
        k = frame.step
        self._enter_step(impl, at, k, frame.mode, self.name in frame.driven)
        values = dict(zip(self._in_names, frame.inputs[self.name]))
        if frame.kind == frames.STEPS:
            times = frame.times
            out = self._step_batch(impl, k, times, values)
            if out is None:
                return True
            self.steps, at.done, at.last_out = k + len(times) - 1, k + len(times) - 2, out
            return False
        t, h = frame.t, frame.h
        if self._rate > 1:  # its own step, the last one cut at stopTime as the base's is
            h = min(self._rate * self.cosim.stepSize, self.cosim.stopTime - t)
        if self.name in frame.slopes:  # iterative coupling's interpolated inputs (check_release checked them)
            impl.set_input_derivatives({n: d for n, d in zip(self._in_names, frame.slopes[self.name]) if d})
        out = self._step_model(impl, k, t, h, values)
        if out is None:
            return True
        self.steps, at.done, at.last_out = k + 1, k, out
        if at.pending_state is not None and at.pending_state[0] == k:
            for i, chunk in enumerate(chunks := frames.state_chunks(at.pending_state[1])):
                self._send(frames.encode(frames.STATE, self.spec.UID, k, i, len(chunks), chunk))
            at.pending_state = None
        return False

    def _on_control(self, frame: frames.Frame) -> tuple[bool, frames.Frame | None]:
        """A frame from the server while stepping that is no STEP or STEPS: (True, None) once this
        node is done (the run's STOP, or its model ended the simulation in an INIT's answer),
        (False, None) once acted on, or (False, the release) for a REPLAY of a release not yet
        answered, to be stepped."""
        impl, at = self.impl, self._stepping
        if frame.kind == frames.STOP:
            self._on_stop(frame)
            return True, None
        if frame.kind == frames.REPLAY:
            # Back after a link cut: the release we may have missed, or already answered.
            inner = frame.release
            if inner.kind in _STEP_KINDS and inner.step > at.done:
                return False, inner
            self._send(at.last_out)
            self._log.info("outputs re-sent", step=at.done + 1)
            return False, None
        if frame.kind == frames.CHECKPOINT:
            if frame.step == at.done + self._rate:  # at the end of this node's last step
                at.pending_state = self._checkpoint_state(impl, frame.step)
            return False, None
        if frame.kind == frames.RESTORE:
            self._restoring, self._phase = _Restoring(first_of_run=False), _RESTORING
            return self._on_restore_piece(frame), None
        if frame.kind == frames.ROLLBACK:
            k, t = frame.step, frame.t
            if at.saved_step != k:
                # Not from this run's server, which rolls back only to the step it just released.
                self.drops.drop("not a release", f"ROLLBACK to step {k}; the state saved is of step {at.saved_step}",
                                self.steps)
                return False, None
            impl.set_state(at.saved)
            self._log.info("rollback", step=k, t=t)
            return False, None
        if frame.kind == frames.INIT:
            return self._on_init(impl, at, frame), None
        # A START: this run has started already.
        self.drops.drop("not a release", "a START while the run is under way", self.steps)
        return False, None

    def _enter_step(self, impl: Node, at: _Stepping, k: int, mode: str, driven: bool) -> None:
        """Before the step from point k (by frame or by call): the state saved for a retake, once
        per point, and the model told of a change of mode."""
        if at.checkpoint and at.saved_step != k:
            at.saved, at.saved_step = impl.get_state(), k
        if (mode, driven) != (at.mode, at.driven):
            at.mode, at.driven = mode, driven
            impl.set_mode(mode, driven)
            self._log.info("mode", step=k, mode=mode, driven=driven)

    def _on_init(self, impl: Node, at: _Stepping, frame: frames.Frame) -> bool:
        """The initialisation phase's inputs at t0: take them and answer with the outputs at step
        0 they make. True if the model failed or ended the simulation there."""
        t0, inputs = frame.t0, frame.inputs
        if at.done != -1 or not self._start_feedthrough():
            self.drops.drop("not a release", "an INIT " + ("after the run's first step" if at.done != -1 else
                            "for a node whose start outputs depend on no input"), self.steps)
            return False
        try:
            impl.start_inputs(dict(zip(self._in_names, inputs[self.name])))
        except Exception as exc:
            self._step_failed(exc, -1, t0)
            return True
        out = self._step_model(impl, -1, t0, None, {})
        if out is None:
            return True
        at.last_out = out
        return False

    def _checkpoint_state(self, impl: Node, step: int) -> tuple[int, bytes] | None:
        """This node's state at point ``step`` for a checkpoint, or None if it cannot give one (the
        server then keeps its previous checkpoint)."""
        if not impl.can_serialize:
            return None
        try:
            return step, impl.serialize_state()
        except Exception as exc:
            self._log.warning("cannot serialise its state for a checkpoint", step=step,
                              error=f"{type(exc).__name__}: {exc}")
            return None

    def _interpolates(self) -> bool:
        return self._interpolating

    def _hello(self, rollback: bool, restart: bool = False) -> bytes:
        stepping = isinstance(self.impl, Node)
        return frames.encode(frames.HELLO, self.spec.UID, {
            "rollback": rollback, "serialize": stepping and self.impl.can_serialize,
            "variableStep": stepping and self.impl.can_vary_step, "restart": restart, "batches": stepping,
            "interpolates": self._interpolating, "startFeedthrough": self._start_feedthrough(),
            "ports": self.spec.wire_ports(), "host": socket.gethostname()[:64]})

    def _start_feedthrough(self) -> dict[str, list[str]]:
        """The model's start_feedthrough within this node's ports, for the server's initialisation."""
        if not isinstance(self.impl, Node):
            return {}
        ins, outs = set(self._in_names), set(self.spec.output_names())
        return {out: [i for i in reads if i in ins] for out, reads in self.impl.start_feedthrough.items()
                if out in outs and any(i in ins for i in reads)}

    def _on_stop(self, frame: frames.Frame) -> None:
        """The server's STOP: the end of the run, or of a failed one, which is this node's failure too."""
        reason = frame.reason
        self._log.info("stop", step=self.steps, reason=reason, waits=self.link.waits if self.link else None,
                       dropped=dict(self.drops.counts))
        if reason not in frames.CLEAN_STOPS:  # the reason names the step where it matters
            raise RunFailedElsewhere(f"node {self.name!r}: the server stopped the run: {reason}")

    def _run_async(self, start: frames.Frame, restart: bool) -> None:
        impl = self.impl
        assert isinstance(impl, AsyncSource)
        self._send(self._hello(False, restart=restart))
        t0, wall0, rt = start.t0, start.wall_t0, start.real_time_factor
        clock = RealTimeClock(t0, wall0, rt) if rt else None
        sim_now, seq = t0, 0
        period = 1.0 / float(self.spec.rate or 30.0)
        while True:
            try:
                for ts, values in impl.samples_until(sim_now):
                    self._send(frames.encode(frames.SAMPLE, self.spec.UID, seq, ts, self._pack_outputs(values)))
                    seq += 1
                    self.samples = seq
            except Exception as exc:
                self._source_failed(exc, sim_now)
            if clock is not None:
                # Real time: sample by the clock, and look for STOP in between. While the
                # server is away (within linkGrace) samples go nowhere; sampling goes on.
                frame = self._next_frame(period)
                sim_now = clock.now()
            else:
                # As fast as possible: the server's releases are the clock.
                frame = self._wait(self.cosim.stepTimeout + 30.0, "release")
                if frame.kind == frames.REPLAY:
                    frame = frame.release
                if frame.kind == frames.STEP:
                    sim_now = frame.t + frame.h
                    self.steps = frame.step + 1
            if frame is not None and frame.kind == frames.STOP:
                self._on_stop(frame)
                return

    def _source_failed(self, exc: Exception, sim_now: float) -> None:
        """Tell the server how an asynchronous source failed (it would otherwise learn only that
        its token went, and with a link grace wait that long to say so), then raise it."""
        if isinstance(exc, NodeRunError):
            message = str(exc)
        elif isinstance(exc, NodeModelError):
            message = f"{exc} (at t={sim_now:g} s)"
        else:
            self._log.exception("source failed", t=sim_now)
            message = (f"node {self.name!r} (an asynchronous source): its model failed at t={sim_now:g} s: "
                       f"{type(exc).__name__}: {exc}")
        self._end(self.steps + 1, sim_now, False, message)

    def _begin_played(self, frame: frames.Frame, restart: bool) -> None:
        self._send(self._hello(False, restart=restart))
        # The outputs it sends are held start values (the server ignores them); the last point
        # whose samples are sent: by the process this one replaces, if any.
        self._played = _Played(self._pack_outputs({p.name: p.start_value() for p in self.spec.output}),
                               frame.step if restart and frame.kind == frames.STEP else -1)

    def _on_played(self, frame: frames.Frame) -> bool:
        """Send the samples due by the point a release reaches, then the word that they are
        sent; True at the run's STOP."""
        impl, at = self.impl, self._played
        assert isinstance(impl, SamplePlayer) and at is not None
        if frame.kind == frames.STOP:
            self._on_stop(frame)
            return True
        if frame.kind == frames.REPLAY:
            frame = frame.release
        point: int | None = None
        if frame.kind == frames.START and at.sent < 0:
            point, t = 0, frame.t0
        elif frame.kind == frames.STEP:
            point, t = frame.step + 1, frame.t + frame.h
        elif frame.kind == frames.RESTORE:
            point, t = frame.step, frame.t
            at.sent = point  # the server's restored histories hold what came before
        if point is not None:  # not a CHECKPOINT, ROLLBACK or the START a resume sends again
            for sample in impl.due(at.sent, point):
                self._send(frames.encode(frames.SAMPLE, self.spec.UID, at.seq, sample.t,
                                         self._pack_outputs(impl.values(sample))))
                at.seq += 1
            at.sent = max(at.sent, point)
            self._send(frames.encode(frames.OUTPUTS, self.spec.UID, point, t, at.held))
            self.steps = point
        return False

    # --- in process -----------------------------------------------------------------

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
        self.link = LocalNodeLink(bus, self.name)
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
        try:
            self._enter_step(impl, at, k, mode, driven)
            if self._listed is not None:  # the values go into the FMU's own buffers
                out = self._listed(t, h, inputs)
            else:
                values = dict(zip(self._in_names, inputs))
                for i, _, _ in self._in_arrays:  # the master's lists stay its own, whatever the model does
                    name = self._in_names[i]
                    values[name] = list(values[name])
                impl.step(t, h, values)
                out = self._pack_outputs(impl.outputs())
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
            frame = self._accept_frame(False, frame)
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


# What a node takes its next frame as: the run's first; after a restarted process's HELLO, a
# state to restore; the pieces of one; a release (a stepping node, or a played recording).
_START, _RESTART, _RESTORING, _STEPPING, _PLAYED = "start", "restart", "restoring", "stepping", "played"


@dataclass
class _Restoring:
    """The pieces of a state to restore as they come, and whether the node has nothing else to
    step from (its process joined the run, or the run's server resumes it)."""

    first_of_run: bool
    chunks: frames.Chunks = field(default_factory=frames.Chunks)
    step: int = -1
    t: float = 0.0


@dataclass
class _Stepping:
    """A stepping node's state between frames: whether it saves its state before each step,
    the state saved and its step, the last step integrated and the outputs sent after it, a
    checkpoint's state to send after the next outputs, and the mode it steps in."""

    checkpoint: bool
    saved_step: int = -1
    saved: Any = None
    done: int = -1
    last_out: bytes = b""
    pending_state: tuple[int, bytes] | None = None
    mode: str | None = None
    driven: bool = False


@dataclass
class _Played:
    """A played recording's state between frames: the held outputs it sends, the last point
    whose samples are sent, and the next sample's sequence number."""

    held: list[Any]
    sent: int
    seq: int = 0
