"""The node runtime: one node in a run, stepped until STOP.

Every frame the master releases goes through one handler, :meth:`NodeRuntime.handle`,
whatever transport carried it (``hycosim.transport.node_side``). How the frames come is the
driver's: over Zenoh (``over_zenoh.ZenohNode.run``) they are pulled from the node's link, with
the link grace and every wait bounded; in process (``in_process.HostedNode.host``) the master
pushes them by calling ``deliver``. An asynchronous source samples on its own clock and runs
over Zenoh only.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import structlog

from hycosim.core import frames
from hycosim.core.config import LoadedProject
from hycosim.core.drops import DropLog
from hycosim.transport.node_side import NodeLink

from hycosim.node.interface import AsyncSource, Node, NodeContext, NodeModelError, SimulationEnded
from hycosim.node.receiving import NodeRunError, Receiver
from hycosim.node.replay import SamplePlayer
from hycosim.node.sending import Outbox, start_feedthrough
from hycosim.node.sources import Played

__all__ = ["NodeRunError", "NodeRuntime", "RunFailedElsewhere"]

# The releases of a step, the frames a stepping node acts on at every point.
_STEP_KINDS = frozenset((frames.STEP, frames.STEPS))


class RunFailedElsewhere(NodeRunError):
    """The server stopped a run that failed (another node lost, a timeout): this node's end too."""


class NodeRuntime:
    """One node in a run: its model set up, every frame of the master's acted on by phase."""

    def __init__(self, loaded: LoadedProject, node_name: str, impl: Node | AsyncSource, endpoint: str,
                 password: str | None = None):
        self.loaded = loaded
        self.spec = loaded.project.node(node_name)
        self.name = node_name
        self.impl = impl
        self.endpoint = endpoint
        self.password = password
        self.cosim = loaded.project.coSimulation
        self._in_names = self.spec.input_names()
        # Multi-rate: this node steps over this many base steps, at every such base point.
        self._rate = loaded.coupling.rates.get(node_name, 1)
        self._log = structlog.get_logger("node").bind(node=node_name)
        self.drops = DropLog(self._log)
        # Where frames come from and go to (run: Zenoh; host: the in-process bus). Over Zenoh
        # the handler's acknowledgements (a STOP after an END) are waited for; in process the
        # master reads what a node sent as soon as its call returns.
        self.receiver = Receiver(self.spec, self.cosim, endpoint, self.drops, self._log, lambda: self.outbox.steps,
                                 loaded.project.driven_in())
        self.outbox = Outbox(self.spec, self.cosim, self.receiver, self._log)
        self.samples = 0  # an asynchronous source's samples sent
        self._phase = PHASE_START  # what the next frame is taken as (see handle)
        self._returning = False  # a START again after a link cut, or the run's, to a restarted process
        self._restoring: _Restoring | None = None
        self._restart_deadline = 0.0
        self._restoring_step = -1  # the step the run was at when a restarted process attached
        self._stepping: _Stepping | None = None
        self._is_player = False  # set once the model is set up
        self._played: Played | None = None
        self.failure: str | None = None  # in process: why this node ended the run, if it failed

    @property
    def steps(self) -> int:
        """The last step whose outputs this node sent."""
        return self.outbox.steps

    @steps.setter
    def steps(self, step: int) -> None:
        self.outbox.steps = step

    @property
    def link(self) -> NodeLink | None:
        """The node's end of its transport, once it is open (None before)."""
        return self.receiver.link

    def _setup(self) -> None:
        try:
            self.impl.setup(node_context(self.loaded, self.spec))
            # Asked of every release a node checks: what it is does not change once set up.
            self.receiver.interpolating = isinstance(self.impl, Node) and self.impl.can_interpolate
            if isinstance(self.impl, Node) and not isinstance(self.impl, SamplePlayer):
                self.receiver.tunable = {name: value for name, value in self.impl.tunable_values().items()
                                         if type(name) is str and frames.tunable_value(value)}
            self._is_player = isinstance(self.impl, SamplePlayer)
        except Exception as exc:
            if isinstance(exc, NodeRunError):
                raise
            if isinstance(exc, NodeModelError):  # a clear message of its own
                raise NodeRunError(str(exc)) from None
            raise NodeRunError(f"node {self.name!r}: its model failed to set up: {type(exc).__name__}: {exc}") from exc

    def handle(self, frame: frames.Frame) -> bool:
        """Act on one frame the master released to this node, accepted already (checked as every
        receiver checks, and meant for it); True once the node is done: the run's STOP, or its
        model ended the simulation. Every transport's frames come here."""
        if self._phase == PHASE_STEPPING:
            return self._on_release(frame)
        if self._phase == PHASE_PLAYED:
            if frame.kind == frames.STOP:
                self._on_stop(frame)
                return True
            self._played.on_frame(frame)
            return False
        if self._phase == PHASE_START:
            return self._on_start(frame)
        if frame.kind == frames.STOP:  # restarting or restoring: the run ended instead
            self._on_stop(frame)
            return True
        if self._phase == PHASE_RESTART:
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
            self.outbox.send(self.outbox.hello(self.impl, False, restart=self._returning))
            # The last point whose samples are sent: by the process this one replaces, if any.
            self._played = Played(self.impl, self.spec.UID, self.outbox,
                                  self.outbox.pack({p.name: p.start_value() for p in self.spec.output}),
                                  frame.step if self._returning and frame.kind == frames.STEP else -1)
            self._phase = PHASE_PLAYED
            return self.handle(frame)
        if frame.kind in _STEP_KINDS:
            # The run is under way: this process is a restart. Say so at once (a node process
            # says HELLO once per run); a server that takes checkpoints restores the run, and
            # this node with it; one that does not stops the run.
            self.outbox.send(self.outbox.hello(self.impl, False, restart=True))
            self._log.info("restarted: waiting for the run to be restored", step=frame.step)
            self._restoring_step = frame.step
            self._restart_deadline = time.monotonic() + self.cosim.attachTimeout + self.cosim.stepTimeout
            self._phase = PHASE_RESTART
            return False
        if frame.kind == frames.RESTORE:
            return self._begin_restore(frame)
        if frame.kind != frames.START:
            raise NodeRunError(f"node {self.name!r}: the run on {self.endpoint} was already under way "
                               "when it attached; a node joins before the run starts")
        self._phase = PHASE_STEPPING
        return not self._begin_stepping(bool(frame.options.get("checkpoint")))

    def _step_model(self, impl: Node, k: int, t: float, h: float | None, inputs: dict[str, Any]) -> bytes | None:
        """Step the model from t by h (h None: only read its outputs at t, k = -1), send its
        outputs at step k + 1 and return them as sent; None if it ended the simulation. A model
        that fails, or whose outputs cannot be sent, is reported to the server (END) and raised."""
        try:
            if h is not None:
                impl.step(t, h, inputs)
            frame = frames.encode(frames.OUTPUTS, self.spec.UID, k + 1, t + (h or 0.0),
                                  self.outbox.pack(impl.outputs()))
            self.outbox.send_outputs(frame, k + 1)
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
            self.outbox.end(k + 1, exc.t, True, f"{exc}", earlier, self._outputs_at_end(impl))
        elif isinstance(exc, NodeRunError):
            self.outbox.end(k + 1, t, False, str(exc))
        elif isinstance(exc, NodeModelError):
            self.outbox.end(k + 1, t, False, f"{exc} (step {k})")
        else:
            self._log.exception("model failed", step=k)
            self.outbox.end(k + 1, t, False, f"node {self.name!r}: its model failed at step {k} (t={t:g} s): "
                                       f"{type(exc).__name__}: {exc}")

    def _outputs_at_end(self, impl: Node | None) -> list[Any] | None:
        """The outputs of a model that ended the simulation, at the time it ended (FMPy records
        them there too: an FMU may be asked for its values after it discarded a step), or None
        where the model cannot give them."""
        if impl is None:
            return None
        try:
            return self.outbox.pack(impl.outputs())
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
                outs.append(self.outbox.pack(impl.outputs()))
            frame = frames.encode(frames.BATCH, self.spec.UID, k + 1, end, outs[-1], outs[:-1])
            self.outbox.send_outputs(frame, k + len(times) - 1)
            return frame
        except Exception as exc:
            self._step_failed(exc, k, t, outs, impl=impl)
            return None  # the model ended the simulation (_step_failed raises for a failure)

    def _begin_restore(self, frame: frames.Frame) -> bool:
        """The first piece of a state to restore, to a process that joins a run under way or to
        one the run's server resumes: the node steps once it is set (see :meth:`_on_restore_piece`)."""
        self._stepping = _Stepping(bool(frame.options.get("checkpoint")) and self.impl.can_rollback)
        self._restoring, self._phase = _Restoring(first_of_run=True), PHASE_RESTORING
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
        self._restoring, self._phase = None, PHASE_STEPPING
        self.outbox.send(self.outbox.hello(self.impl, impl.can_rollback))
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
        first, self._restoring, self._phase = self._restoring.first_of_run, None, PHASE_STEPPING
        if first:
            raise NodeRunError(f"node {self.name!r}: the state the server sent to restore could not be set "
                               f"(see {self.name}'s log)")
        return False

    def _begin_stepping(self, checkpoint: bool) -> bool:
        """Answer the START: HELLO and the outputs at t0; False if the model ended the simulation there."""
        impl = self.impl
        assert isinstance(impl, Node)
        at = self._stepping = _Stepping(checkpoint and impl.can_rollback)
        self.outbox.send(self.outbox.hello(self.impl, impl.can_rollback))
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
        k, mode, driven = frame.step, frame.mode, self.name in frame.driven
        if at.checkpoint or mode != at.mode or driven != at.driven:  # else _enter_step has nothing to do
            self._enter_step(impl, at, k, mode, driven)
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
                self.outbox.send(frames.encode(frames.STATE, self.spec.UID, k, i, len(chunks), chunk))
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
            self.outbox.send(at.last_out)
            self._log.info("outputs re-sent", step=at.done + 1)
            return False, None
        if frame.kind == frames.CHECKPOINT:
            if frame.step == at.done + self._rate:  # at the end of this node's last step
                at.pending_state = _checkpoint_state(impl, frame.step, self._log)
            return False, None
        if frame.kind == frames.RESTORE:
            self._restoring, self._phase = _Restoring(first_of_run=False), PHASE_RESTORING
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
        if frame.kind == frames.TUNE:
            try:
                impl.set_parameters(dict(frame.values))
            except Exception as exc:  # as a step that failed: the server stops the run with its words
                self._step_failed(exc, frame.step, frame.t)
                return True, None
            self._log.info("parameters", step=frame.step, values=frame.values)
            return False, None
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
        """The initialisation phase's inputs at t0: take them (``leave``: and leave the model's
        initialisation mode) and answer with the outputs at step 0 they make. True if the model
        failed or ended the simulation there."""
        t0, inputs, leave = frame.t0, frame.inputs, frame.leave
        if at.done != -1 or not (leave or start_feedthrough(self.impl, self.spec)):
            self.drops.drop("not a release", "an INIT " + ("after the run's first step" if at.done != -1 else
                            "for a node whose start outputs depend on no input"), self.steps)
            return False
        values = dict(zip(self._in_names, inputs[self.name]))
        try:
            if leave:
                impl.finish_initialization(values)
            else:
                impl.start_inputs(values)
        except Exception as exc:
            self._step_failed(exc, -1, t0)
            return True
        out = self._step_model(impl, -1, t0, None, {})
        if out is None:
            return True
        at.last_out = out
        return False

    def _on_stop(self, frame: frames.Frame) -> None:
        """The server's STOP: the end of the run, or of a failed one, which is this node's failure too."""
        reason = frame.reason
        self._log.info("stop", step=self.steps, reason=reason, waits=self.link.waits if self.link else None,
                       dropped=dict(self.drops.counts))
        if reason not in frames.CLEAN_STOPS:  # the reason names the step where it matters
            raise RunFailedElsewhere(f"node {self.name!r}: the server stopped the run: {reason}")


def _checkpoint_state(impl: Node, step: int, log: Any) -> tuple[int, bytes] | None:
    """A node's state at point ``step`` for a checkpoint, or None if it cannot give one (the
    server then keeps its previous checkpoint)."""
    if not impl.can_serialize:
        return None
    try:
        return step, impl.serialize_state()
    except Exception as exc:
        log.warning("cannot serialise its state for a checkpoint", step=step, error=f"{type(exc).__name__}: {exc}")
        return None


def node_context(loaded: LoadedProject, spec: Any) -> NodeContext:
    """What a node's model is set up with: its entry's ports and parameters, the run's clock."""
    cosim = loaded.project.coSimulation
    params = dict(spec.parameters)
    if spec.rate is not None:
        params.setdefault("rate", spec.rate)
    project_dir = loaded.path.parent if loaded.path else None
    return NodeContext(spec.nodeName, spec.UID, list(spec.input), list(spec.output), params,
                       cosim.stepSize, cosim.startTime, **({"project_dir": project_dir} if project_dir else {}),
                       real_time=cosim.real_time_factor(), stop_time=cosim.stopTime)


# What a node takes its next frame as: the run's first; after a restarted process's HELLO, a
# state to restore; the pieces of one; a release (a stepping node, or a played recording).
PHASE_START, PHASE_RESTART, PHASE_RESTORING = "start", "restart", "restoring"
PHASE_STEPPING, PHASE_PLAYED = "stepping", "played"


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
