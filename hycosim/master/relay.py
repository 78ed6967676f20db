"""The relay server's co-simulation loop: attach, then the macro-step barrier until stopTime.

Read top to bottom, :meth:`Relay.run` and :meth:`Relay._loop` are the whole algorithm:

1. wait until every node holds a liveliness token (attachTimeout names the missing ones);
2. :meth:`_begin`: START, every stepping node reports its outputs at t0 (then the
   initialisation phase), or, resuming, every node gets its state at the last checkpoint;
   :meth:`_plan`: what the nodes said they can take part in (localisation, iteration, step
   control, batches, checkpoints);
3. at each macro-step point, :meth:`_arrive`: a checkpoint if one is due, the guards (maybe a
   mode switch), the outputs routed along the links active in the mode, pacing; then
   :meth:`_step_from`: release the nodes to integrate T_k → T_k+H (Jacobi: all at once;
   Gauss-Seidel: in order) by the run's strategy (plain; iterated or size-controlled, whose
   loops of retakes are server.retakes' iterate_step and control_step; located around a
   guard crossing by server.localisation's bisection), record point k while they step, and
   gather their outputs at T_k+H (:meth:`gather`, the releases' ledger in server.ledger
   sorting the answers);
4. STOP at stopTime, on Ctrl-C, or on a fault, with everything recorded so far on disk.

The transport (Zenoh sessions and keys, or calls in one process) is given as a
:class:`~hycosim.transport.server_side.Transport`; the loop does not know which (only the
gateway for bridge FMUs asks for the transport's Zenoh session).
"""

from __future__ import annotations

import functools
import math
import os
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator, Mapping, Protocol

import structlog

from hycosim.core import frames, signals
from hycosim.core.schema import FREE_MODE, ScenarioAction
from hycosim.core.config import LoadedProject
from hycosim.transport.inbox import LOCAL
from hycosim.transport.keys import ProjectKeys
from hycosim.transport.local_bus import DirectStep
from hycosim.transport.session import FrameTooLarge
from hycosim.core.sim_clock import RealTimeClock

from hycosim.master import checkpoints, initialisation, plans
from hycosim.transport.answer_budget import AnswerBudget
from hycosim.master.async_sources import SampleHistory
from hycosim.master.coordinator import Coordinator, GuardEvaluationError
from hycosim.bridge.gateway import Gateway, GatewayError
from hycosim.master.intake import Dropped, Intake, port_mismatch
from hycosim.master.ledger import ENDED, LATER, TAKE, Ledger
from hycosim.master.localisation import bisect_crossing
from hycosim.master.interpolation import STARTUP_SPLIT, InputTrack
from hycosim.master.recorder import Recorder, RecordError
from hycosim.master.retakes import IterationLog, StepSizer, control_step, input_change, iterate_step
from hycosim.master.observers import Observer, PointValues
from hycosim.master.scenario import Scenario
from hycosim.master.routing import OutputView, Router
from hycosim.master.status_view import LatestPoints
from hycosim.transport.server_side import Transport

RECENT_KEPT = 4096  # the latest points kept for the status answers


class RunError(RuntimeError):
    """A run that cannot go on; the message names the node and the step."""


class _Recover(Exception):
    """A node's process was started again mid-run: the run goes back to its last checkpoint."""

    def __init__(self, node: str, step: int, cause: str):
        super().__init__(cause)
        self.node, self.step, self.cause = node, step, cause


@dataclass
class _PendingCheckpoint:
    """A checkpoint asked for at point ``step``: the server's state then, and the nodes' as they come."""

    step: int
    server: dict[str, Any]
    states: dict[str, bytes] = field(default_factory=dict)
    chunks: dict[str, frames.Chunks] = field(default_factory=dict)


class _ModelEnded(Exception):
    """A node's model ended the simulation (an FMU that asked to terminate): the run's records
    end at the last macro-step point every node reached, then the point where it ended."""


@dataclass(slots=True)
class _Point:
    """Where the loop is: point k at time t, the j-th of the grid origin + j·H (a located event
    starts a new grid at its time), and how the step to it went."""

    k: int
    t: float
    origin: float
    j: int
    localised: dict[str, Any]  # the located event that ended the step to it
    arrivals: dict[str, float]  # each node's answer, seconds after its release
    wait: float  # from the release to the last answer
    takes: int = 1  # of the step to it (iterated or size-controlled)


@dataclass(slots=True)
class _Seen:
    """Point k as the loop saw it before stepping from it: what its record holds."""

    mode: str
    outputs: dict[str, list[Any]]
    view: OutputView
    ages: dict[str, float | None]
    lateness: float | None
    holder: str  # the node whose answer came last
    stepped: list[str] | None  # a multi-rate run's nodes stepped from it


# A node's own words about why it ended or failed are shown and recorded up to this length.
_MESSAGE_MAX = 2000


@dataclass
class Progress:
    """What the server reports while running (read by ``hycosim run``'s progress bar)."""

    step: int = 0
    t: float = 0.0
    mode: str = FREE_MODE
    steps_per_s: float = 0.0
    attached: list[str] = field(default_factory=list)
    lateness_s: float | None = None  # a paced run's, at the last point


@dataclass
class _Ending:
    """A node's model that ended the run: ``by`` (its node, step, t and words) once one did.
    While the release it ended in is gathered: the nodes that ended in it (``inside``) and the
    release's arrivals (the others' outputs are gathered first; inside a batched release the
    points the ended steps before reached are recorded), and the ended node's outputs at its
    end (``values``, its END's)."""

    by: dict[str, Any] | None = None
    inside: set[str] = field(default_factory=set)
    arrivals: dict[str, float] = field(default_factory=dict)
    values: list[Any] | None = None


class _Rate:
    """The run's steps a second since the loop began, handed with the progress to
    ``on_progress`` at most every ``every`` seconds and at the end."""

    def __init__(self, every: float, on_progress: Callable[[Progress], None] | None):
        self.every, self.on_progress = every, on_progress
        self.began, self.k0, self.reported = 0.0, 0, 0.0

    def begin(self, k: int) -> None:
        self.began, self.k0 = time.perf_counter(), k

    def point(self, progress: Progress, k: int, now: float) -> None:
        if self.on_progress is not None and now - self.reported >= self.every:
            self.reported = now
            progress.steps_per_s = (k - self.k0) / (now - self.began) if now > self.began else 0.0
            self.on_progress(progress)

    def end(self, progress: Progress, k: int) -> float | None:
        """The rate over the whole loop (None if no time passed), reported once more."""
        elapsed = time.perf_counter() - self.began
        rate = (k - self.k0) / elapsed if elapsed > 0 else None
        if self.on_progress is not None:
            progress.steps_per_s = rate or 0.0
            self.on_progress(progress)
        return rate


class PointGate(Protocol):
    """When the step from a macro-step point is taken (the run's points other than the last)."""

    def hold(self, step: int, t: float) -> None:
        """Return once the step from point ``step`` (at ``t``) may be taken. The relay is at
        the point meanwhile: its outputs gathered and its inputs routed, nothing stepping."""


class _OpenGate:
    """Every step at once: a run from the command line."""

    def hold(self, step: int, t: float) -> None:
        return None


_OPEN = _OpenGate()


class Relay:
    def __init__(self, loaded: LoadedProject, transport: Transport, recorder: Recorder,
                 progress_every_s: float = 0.0, on_progress: Any = None,
                 gateway_address: tuple[str, int] | None = None, gateway_required: bool = False,
                 resume: int | None = None, gate: PointGate | None = None,
                 scenario: list[ScenarioAction] | None = None):
        self.loaded = loaded
        # Who decides when the step from each point is taken: at once, or a Python caller
        # driving the run (hycosim.open), which may look at the point meanwhile.
        self._gate: PointGate = gate or _OPEN
        self.project = loaded.project
        self.cosim = self.project.coSimulation
        self.keys = ProjectKeys(self.project.projectName)
        self.transport = transport
        self.recorder = recorder
        self.coordinator = Coordinator(self.project.events, loaded.guards)
        self.router = Router(loaded)
        # Overrides of inputs in time (the project's scenario, --scenario, a Python caller's).
        self.scenario = Scenario(self.project, loaded.routes, [*self.project.scenario, *(scenario or [])])
        # Who sees each point recorded (observers.py); a row goes to the recorder alone until one is added.
        self.observers: list[Observer] = []
        self._values = PointValues(self.project)
        self._row = recorder.row
        self._input_labels = {n.nodeName: [f"{n.nodeName}.{p.name}" for p in n.input] for n in self.project.nodeLists}
        # Iterative coupling and the error-controlled step, once the nodes said they can take part.
        self.iteration: IterationLog | None = None
        self.sizer: StepSizer | None = None
        # Iterative coupling's interpolated inputs, and how many short steps start the run for them.
        self.track: InputTrack | None = None
        self._short_steps = 0
        self.intake = Intake(self.project.nodeLists)
        self.stepping = [n.nodeName for n in self.project.stepping_nodes()]
        self.coupling = loaded.coupling
        # Each stepping node's outstanding step and the answers kept for later points; batched
        # releases (STEPS, multi-rate) span this many base steps once the nodes said they can.
        self.ledger = Ledger(self.stepping, [n.nodeName for n in self.project.paced_nodes()], self.coupling.rates)
        self._span = 1
        self.messages = {"releases": 0, "received": 0}  # release frames sent, node frames taken in
        self._point = 0  # the point the loop is at: the last recorded should a node end the run now
        self._last_release_of: dict[str, bytes] = {}  # node → the last release that named it
        self._last_point = math.inf  # the index of the point at stopTime, on a grid from startTime
        # Asynchronous nodes played from a recording take part in the barrier: each point waits
        # for the samples the recorded run had by then, so that a replay gives the same values.
        self.paced = [n.nodeName for n in self.project.paced_nodes()]
        self._everyone = [*self.stepping, *self.paced]  # who is gathered at every point of a single-rate run
        self._names = {n.nodeName for n in self.project.nodeLists}
        self.histories = {n.nodeName: SampleHistory([p.start_value() for p in n.output])
                          for n in self.project.async_nodes()}
        # Async nodes' outputs as seen at the current point (hold), for guards and records.
        self.outputs: dict[str, list[Any]] = {
            n.nodeName: [p.start_value() for p in n.output] for n in self.project.nodeLists}
        self.alive: set[str] = set()
        self.capabilities: dict[str, dict[str, Any]] = {}
        # Nodes whose token (re)appeared and whose HELLO has not come since: a HELLO is taken only
        # from a node new to the run or one whose process may have changed, so that a forged
        # one (the UIDs are in the project file) cannot pass for a restart and stop the run.
        self._fresh: set[str] = set()
        self.lost: dict[str, float] = {}  # node → when its token went, while within linkGrace
        self.reattached: dict[str, int] = {}
        self.ending = _Ending()  # a node's model that ended the run
        self.latest = LatestPoints(self.cosim.startTime, RECENT_KEPT, FREE_MODE)  # for the status answers
        self.answers = AnswerBudget()  # status answers a second: anyone may ask
        self._last_release: bytes | None = None
        self._start_frame: bytes | None = None
        # Checkpoints (coSimulation.checkpointEvery): on once every stepping node said it can
        # serialise its state; the one being gathered; restores done (node, steps, cause, time).
        self._checkpoints = False
        self._starting = False  # the START's answers are gathered: a lost node may be started again
        self._pending: _PendingCheckpoint | None = None
        self.checkpoints_taken = 0
        self.recoveries: list[dict[str, Any]] = []
        self._restoring = False
        self._went: dict[str, float] = {}  # node → when its token last went (recovery times are measured from it)
        # Go on from the run directory's last checkpoint (its server died after recording this many steps).
        self._resume = resume
        self.progress = Progress()
        self._rate = _Rate(progress_every_s, on_progress)
        self._clock: RealTimeClock | None = None  # a real-time run's (coSimulation.realTimeFactor)
        self._checkpoint_at = self.cosim.startTime  # the next checkpoint's time
        self._localising = False  # whether guard crossings are located (event localisation)
        self._direct: Mapping[str, DirectStep] | None = None  # in process, where the plan allows: steps as calls
        self._log = structlog.get_logger("server").bind(project=self.project.projectName)
        self._stop_requested = threading.Event()
        self._gateway_address = gateway_address
        self._gateway_required = gateway_required
        self.gateway: Gateway | None = None

    # --- wiring -------------------------------------------------------------------

    def _dropped(self) -> dict[str, int]:
        """What was dropped, by reason: the frames the intake refused, the status questions over budget."""
        refused = self.answers.refused
        return {**self.intake.dropped, **({"status over budget": refused} if refused else {})}

    def status(self, since: int | None = None) -> dict[str, Any]:
        """Who is attached and where the run is, for ``hycosim status`` and the dashboard (read
        from Zenoh's thread: copies of what the loop changes, each taken at once under the GIL).
        ``since``: also the recent points after that step (server.status_view)."""
        restarts: dict[str, int] = {}
        for r in list(self.recoveries):
            restarts[r["node"]] = restarts.get(r["node"], 0) + 1
        nodes = []
        for n in self.project.nodeLists:
            host = self.capabilities.get(n.nodeName, {}).get("host")
            nodes.append({"name": n.nodeName, "uid": n.UID, "async": n.asynchronous,
                          "input": n.input_names(), "output": n.output_names(),
                          "host": host if type(host) is str else None, "restarts": restarts.get(n.nodeName, 0)})
        return {"project": self.project.projectName, "attached": sorted(self.alive), "lost": sorted(self.lost),
                "expected": [n.nodeName for n in self.project.nodeLists], "nodes": nodes,
                "run": self.recorder.run_dir.name, "stopTime": self.cosim.stopTime,
                "lateness_s": self.progress.lateness_s, "dropped": self._dropped(),
                **self.latest.answer(time.perf_counter(), since)}

    @property
    def stopped(self) -> bool:
        """Whether the run was asked to stop before its stop time (a run driven from Python, closed)."""
        return self._stop_requested.is_set()

    def request_stop(self) -> None:
        """Ask the loop to stop at the next macro-step point (thread-safe)."""
        self._stop_requested.set()

    # --- the loop -----------------------------------------------------------------

    def run(self) -> None:
        polls = self.project.polls_before_blocking(os.cpu_count())
        self.recorder.meta["server_polls"] = polls
        self.inbox, self.release = self.transport.open(self.keys, polls, self.cosim.lowLatency, self.status,
                                                       self.answers)
        status_text, reason = "failed", ""
        signals.stop_once()
        try:
            self._start_gateway()
            self._wait_for_nodes()
            try:
                self._loop()
            except _ModelEnded:  # at the START: no macro step was taken
                pass
            status_text = frames.STOP_COMPLETED if not self._stop_requested.is_set() else frames.STOP_STOPPED
            if self.ending.by is not None:
                self.recorder.meta["ended_by"] = self.ending.by
        except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM or SIGHUP
            status_text, reason = "interrupted", signals.describe(exc)
            self.recorder.meta["stopped_by"] = {"signal": signals.name_of(exc),
                                                "step": self.progress.step, "t": self.progress.t}
            raise
        except (RunError, RecordError) as exc:
            reason = str(exc)
            raise
        finally:
            signals.ignore_stops()
            self.recorder.free_reserve()
            self._broadcast_stop(status_text if not reason else reason)
            self._await_departures()
            if self.gateway is not None:
                self.gateway.close(reason or status_text)
            self.intake.drops.flush(self.progress.step)
            self.recorder.close(status_text, reason=reason, dropped_frames=self._dropped(),
                                non_finite=self.intake.non_finite,
                                reattached=dict(self.reattached), server_waits=self.inbox.waits,
                                messages=dict(self.messages),
                                checkpoints_taken=self.checkpoints_taken,
                                samples_received={n: h.received for n, h in self.histories.items()})
            self.transport.close()
            self.inbox.close()
            for observer in self.observers:
                try:
                    observer.run_ended(status_text)
                except Exception:  # noqa: BLE001 - the run is over and recorded; a broken observer changes nothing
                    self._log.exception("observer failed at the run's end", observer=type(observer).__name__)

    def _await_departures(self, timeout: float = 3.0) -> None:
        """After STOP, give the nodes a moment to leave before this session closes: closing at
        once can drop the STOP still queued for a node, which then sees only the server vanish."""
        deadline = time.monotonic() + timeout
        try:
            while self.alive and time.monotonic() < deadline:
                msg = self.inbox.recv(deadline - time.monotonic())
                if msg is None:
                    break
                if msg[0] == LOCAL:
                    live = frames.decode(msg[1])
                    if not live.alive:
                        self.alive.discard(live.node)
        except Exception:  # shutting down: never mask the run's own outcome
            pass

    def _start_gateway(self) -> None:
        if self._gateway_address is None:
            return
        host, port = self._gateway_address
        try:
            self.gateway = Gateway(
                self.project.stepping_nodes(), self.transport.session, self.keys, host, port,
                drop=self.intake.drop, rates=self.coupling.rates, stop_time=self.cosim.stopTime)
        except GatewayError as exc:
            if self._gateway_required:
                raise RunError(str(exc)) from None
            self._log.warning("gateway disabled", reason=str(exc))
            self.recorder.meta["gateway"] = f"disabled: {exc}"
            return
        self.recorder.meta["gateway"] = self.gateway.address

    def _broadcast_stop(self, reason: str) -> None:
        try:
            self.release.put(frames.encode(frames.STOP, self.progress.step, reason))
        except Exception:  # the session may be gone with Ctrl-C
            pass

    def _wait_for_nodes(self) -> None:
        expected = {n.nodeName for n in self.project.nodeLists}
        deadline = time.monotonic() + self.cosim.attachTimeout
        while not expected <= self.alive:
            msg = self.inbox.recv(deadline - time.monotonic())
            if msg is None:
                missing = sorted(expected - self.alive)
                raise RunError(f"timed out after {self.cosim.attachTimeout:g} s waiting for node(s) "
                               f"{', '.join(missing)} to attach to {self.project.serverIP}")
            self.take_in(*msg, step=-1, collecting=False)
        self._log.info("all nodes attached", nodes=sorted(self.alive))

    def take_in(self, key: str, payload: bytes, step: int, collecting: bool) -> tuple[str, frames.Frame] | None:
        """Take in one message of the inbox (``key``: the node's ``up`` key, or LOCAL for a
        liveliness change) while point ``step`` is gathered (-1: while the nodes attach).
        Liveliness, samples, states and HELLOs are handled here; a node's OUTPUTS, BATCH or END
        is returned as (node, frame); anything the intake refuses is dropped and counted."""
        if key == LOCAL:
            live = frames.decode(payload)
            if live.node in self._names:  # not the server's own token, nor one no node of this project holds
                self._on_live(live.node, live.alive, step, collecting)
            return None
        node = ProjectKeys.last_chunk(key)
        try:
            frame = self.intake.accept(node, payload)
        except Dropped as exc:
            self.intake.drop(exc.reason, exc.detail, step, node if node in self._names else "")
            return None
        if frame.kind == frames.SAMPLE:
            self.histories[node].add(float(frame.t), frame.values)
            # Received while point ``step`` is gathered: usable from that point on.
            self.recorder.sample(node, max(step, 0), float(frame.t), frame.values)
            return None
        if frame.kind == frames.STATE:
            self._on_state(node, frame, step)
            return None
        if frame.kind == frames.HELLO:
            self._on_hello(node, frame.capabilities, step)
            return None
        self.messages["received"] += 1
        return node, frame

    def _on_live(self, node: str, alive: bool, step: int, collecting: bool) -> None:
        """A node's liveliness token came or went (``step`` -1: while the nodes attach)."""
        if alive:
            self.alive.add(node)
            if node not in self.capabilities or node in self.lost:
                self._fresh.add(node)
            self.progress.attached = sorted(self.alive)
            self._log.info("node attached", node=node, step=step)
            if node in self.lost:
                del self.lost[node]
                self.reattached[node] = self.reattached.get(node, 0) + 1
                # An asynchronous source that restarted needs the run's START (its clock);
                # the others, a played one included, the last release.
                last = (self._start_frame if self.project.node(node).asynchronous and node not in self.paced
                        else self._last_release_of.get(node, self._last_release))
                if last is not None:
                    try:
                        self.release.put(frames.encode(frames.REPLAY, node, last))
                    except FrameTooLarge as exc:
                        raise RunError(f"cannot replay the last release to {node!r}: {exc}") from None
        elif node in self.alive:
            self.alive.discard(node)
            self._went[node] = time.monotonic()
            if step < 0:
                # Gone before the run started: nothing of it is lost, and a new process of it
                # attaches as the first did (its HELLO is taken as a first one).
                self.capabilities.pop(node, None)
                self._fresh.discard(node)
                return
            if step >= 0 and self._grace() > 0:
                self.lost[node] = time.monotonic()
                self._log.warning("node lost, waiting for it", node=node, step=step, grace_s=self._grace())
            elif collecting or step >= 0:
                why = self.recorder.meta.get("checkpoints", "")
                raise RunError(f"node {node!r} was lost at step {step} (t={self._time(step):g} s): "
                               "its liveliness token disappeared (process killed or link lost)"
                               + (f"; the run cannot go on from a checkpoint (checkpoints {why})"
                                  if self.cosim.checkpointEvery is not None else ""))

    def _on_hello(self, node: str, said: dict[str, Any], step: int) -> None:
        """A node's HELLO: what it can do, from a node new to the run or a new process of one."""
        if node in self.capabilities and node not in self._fresh and node not in self.lost:
            self.intake.drop("duplicate hello", f"{node} said HELLO again while its process held its token",
                             step, node)
            return
        self._fresh.discard(node)
        if node in self.capabilities and step > 0 and said.get("restart") is True:
            self._restarted(node, step)
            if self.project.node(node).asynchronous:
                return  # a source lives on the wall clock: it just goes on sampling
        elif node in self.capabilities and step > 0 and not self._restoring:
            # A node process says HELLO once: this is a new process, whose model starts
            # from scratch while the others are at step k. Not a link cut to wait out.
            # (While the START is collected, a fresh start is all that was asked of it.)
            raise RunError(f"node {node!r} was started again at step {step} (t={self._time(step):g} s) while "
                           "the run was under way: the state it had is gone, so the run cannot go on; "
                           "start the run again")
        self.capabilities[node] = dict(said)
        self._check_ports(node, self.capabilities[node].get("ports"))

    def _grace(self) -> float:
        """How long a lost node is waited for: its linkGrace, or with checkpoints (and while the
        START is answered, when no node has stepped) its restart (attachTimeout: a new process
        attaches as a first one does)."""
        return max(self.cosim.linkGrace, self.cosim.attachTimeout if self._checkpoints or self._starting else 0.0)

    def _restarted(self, node: str, step: int) -> None:
        """A node's new process said HELLO mid-run: go back to the last checkpoint, or say why not."""
        at = f"at step {step} (t={self._time(step):g} s)"
        if self.project.node(node).asynchronous and self._checkpoints:
            self._note_recovery({"node": node, "step": step, "t": self._time(step), "cause": "restarted",
                                 "restored": None, "at": time.time()})
            self._log.warning("asynchronous node restarted", node=node, step=step)
            return
        if not self._checkpoints:
            why = self.recorder.meta.get("checkpoints", "off")
            raise RunError(f"node {node!r} was started again {at} while the run was under way: the state it had "
                           f"is gone and the run cannot go back to a checkpoint (checkpoints {why}); start the run again")
        raise _Recover(node, step, "restarted")

    def _on_state(self, node: str, frame: frames.Frame, step: int) -> None:
        """A piece of a node's state for the checkpoint being gathered; the checkpoint is written
        once every stepping node's state is whole."""
        at = frame.step
        p = self._pending
        if p is None or at != p.step or self.project.node(node).asynchronous:
            self.intake.drop("stale state", f"{node} sent its state at step {at}, no checkpoint of it is gathered",
                             step, node)
            return
        data = p.chunks.setdefault(node, frames.Chunks()).add(at, frame.index, frame.count, frame.chunk)
        if data is None:
            return
        p.states[node] = data
        if len(p.states) < len(self.stepping):
            return
        self._pending = None
        try:
            path = checkpoints.write(self.recorder.run_dir, p.step, p.server, p.states, self.loaded.digest)
        except checkpoints.CheckpointError as exc:
            self._log.warning("checkpoint not written", step=p.step, error=str(exc))
            self.recorder.meta["checkpoint_error"] = str(exc)
            return
        self.checkpoints_taken += 1
        self.recorder.meta["last_checkpoint"] = {"step": p.step, "t": p.server["t"], "path": str(path)}
        self._log.info("checkpoint", step=p.step, t=p.server["t"], bytes=sum(map(len, p.states.values())))

    def _said(self) -> dict[str, dict[str, Any]]:
        """What each stepping node said it can do (nothing, if it said no HELLO)."""
        return {n: self.capabilities.get(n, {}) for n in self.stepping}

    def _checkpoint_plan(self) -> bool:
        """Whether checkpoints are taken; say why not in the metadata."""
        plan = plans.checkpoints(self.cosim, self._said())
        self.recorder.meta["checkpoints"] = plan.words
        if plan.why:
            self._log.warning("no checkpoints", cannot_serialise=plan.why)
        return plan.on

    def _next_checkpoint(self, t: float) -> float:
        return checkpoints.next_time(t, self.cosim.startTime, self.cosim.checkpointEvery)

    def _take_checkpoint(self, k: int, t: float, origin: float, j: int, localised: dict[str, Any], h: float) -> None:
        """Ask every stepping node for its state at point k (they send it after their next
        outputs) and keep the server's own, records included, until theirs are in."""
        if self._pending is not None:
            missing = sorted(set(self.stepping) - set(self._pending.states))
            self._log.warning("checkpoint abandoned", step=self._pending.step, missing=missing)
        server = {"step": k, "t": float(t), "origin": float(origin), "j": j, "mode": self.coordinator.mode,
                  "disarmed": sorted(self.coordinator.disarmed),
                  "outputs": {n: list(v) for n, v in self.outputs.items()},
                  "inputs": {n: list(v) for n, v in self.router.inputs.items()},
                  "histories": {n: h.snapshot() for n, h in self.histories.items()},
                  "records": self.recorder.positions(k), "localised": localised, "h": float(h),
                  "track": self.track.snapshot() if self.track is not None else None}
        self._pending = _PendingCheckpoint(k, server)
        self.release.put(frames.encode(frames.CHECKPOINT, k))

    def _restore(self, cause: _Recover) -> tuple[dict[str, Any], dict[str, float], float]:
        """Take the whole run back to its last readable checkpoint: every stepping node gets its
        state back and answers with its outputs there, the records are cut back to it, and the
        server takes its own state back. Return the server's state, arrivals and wait."""
        began = time.monotonic()
        while True:
            cp, passed = checkpoints.latest(self.recorder.run_dir, self.loaded.digest, project=self.project)
            for reason in passed:
                self._log.warning("checkpoint passed over", reason=reason)
                self.recorder.meta.setdefault("checkpoints_passed_over", []).append(reason)
            if cp is None:
                raise RunError(f"node {cause.node!r} was started again at step {cause.step}, and no checkpoint "
                               f"of the run could be read to go on from"
                               + (f": {'; '.join(passed)}" if passed else ""))
            self._log.warning("restoring checkpoint", node=cause.node, lost_at=cause.step, step=cp.step)
            self._restoring = True
            try:
                self._pending = None
                self._fresh.update(self.stepping)
                self._send_restore(cp)
                if cause.node == "server" and self._start_frame is not None:
                    start = frames.decode(self._start_frame)._replace(t0=cp.server["t"])
                    self._start_frame = frames.encode(frames.START, *start)
                    self.release.put(self._start_frame)
                released = time.perf_counter()
                self.ledger.expect_all(cp.step, released)
                arrivals = self.gather(cp.step, released)
                wait = time.perf_counter() - released
            except _Recover as again:  # another process restarted meanwhile: once more
                cause = again
                continue
            finally:
                self._restoring = False
            break
        restored = self._apply(cp)
        self._note_recovery({"node": cause.node, "step": cause.step, "t": self._time(cause.step),
                             "cause": cause.cause, "restored": cp.step, "restored_t": cp.server["t"],
                             "seconds": round(time.monotonic() - self._went.get(cause.node, began), 3),
                             "at": time.time()})
        return restored, arrivals, wait

    def _note_recovery(self, entry: dict[str, Any]) -> None:
        """A restart or resume, in the metadata at once (the run may yet die)."""
        self.recoveries.append(entry)
        earlier = self.recorder.meta.get("recoveries")  # a resumed run's, from its meta.json
        self.recorder.meta["recoveries"] = (earlier if type(earlier) is list else []) + [entry]
        self.recorder.write_meta()

    def _restore_track(self, s: dict[str, Any], what: str) -> None:
        """The interpolated inputs' points before a checkpoint's (its server state ``s``), so that
        the steps from it are taken on the polynomials they were taken on before."""
        if self.track is None:
            return  # not yet planned (a resume plans it once the nodes are back) or no interpolation
        try:
            self.track.restore(s.get("track"))
        except ValueError as exc:
            raise RunError(f"{what}: {exc}") from None
        ours = self.router.inputs
        if any(set(values) != set(ours) or any(len(values[n]) != len(ours[n]) for n in ours)
               for _, values in self.track.snapshot()["points"]):
            raise RunError(f"{what} does not fit the project: its interpolated inputs differ")

    def _saves_states(self) -> bool:
        """Whether nodes save their state before each step, so that a step can be taken again."""
        cosim = self.cosim
        return cosim.eventTolerance is not None or cosim.iterate is not None or cosim.stepControl is not None

    def _send_restore(self, cp: checkpoints.Checkpoint) -> None:
        # As START's: a node started again must save its state before each step as the others do,
        # or the retakes of iterative coupling and step control would step it on from where it was.
        options = {"checkpoint": self._saves_states()}
        for node in self.paced:  # no state: a played source goes on from the checkpoint's point
            self.release.put(frames.encode(frames.RESTORE, node, cp.step, cp.server["t"], 0, 1, b"", options))
        for node in self.stepping:
            if node not in cp.states:
                raise RunError(f"checkpoint {cp.path} holds no state of node {node!r}")
            pieces = frames.state_chunks(cp.states[node])
            for i, chunk in enumerate(pieces):
                self.release.put(frames.encode(frames.RESTORE, node, cp.step, cp.server["t"], i, len(pieces),
                                               chunk, options))

    def _apply(self, cp: checkpoints.Checkpoint) -> dict[str, Any]:
        """The server's own state at the checkpoint (read as fitting the project), and its
        records cut back to it."""
        s = cp.server
        for node, values in self.outputs.items():
            if not self.project.node(node).asynchronous and values != s["outputs"][node]:
                self._log.warning("restored outputs differ from the checkpoint's", node=node, step=cp.step)
        self._restore_track(s, f"checkpoint {cp.path}")
        self.coordinator.mode = s["mode"]
        self.coordinator.disarmed = set(s["disarmed"])
        for node in self.outputs:
            self.outputs[node] = list(s["outputs"][node])
            self.router.inputs[node][:] = s["inputs"][node]
        self.recorder.cut(s["records"], steps=s["step"])
        for node, history in self.histories.items():
            newer = [(t, v) for t, v in history.snapshot()["samples"]]
            history.restore(s["histories"].get(node, {"samples": [], "received": 0}))
            for t, v in newer:  # samples taken since keep their place: a source is not rolled back
                if history.add(t, v):
                    self.recorder.sample(node, s["step"], t, v)  # as if received again at the checkpoint
        return s

    def _check_ports(self, node: str, theirs: Any) -> None:
        """Stop the run if a node's copy of the project file gives it other ports than ours:
        its frames would all be dropped and the run would only time out."""
        differ = port_mismatch(self.project.node(node), theirs)
        if differ is not None:
            raise RunError(f"node {node!r} attached with another version of its entry in the project file: "
                           f"{differ}. Give every process the same project file")

    def _time(self, step: int) -> float:
        return self.cosim.startTime + max(step, 0) * self.cosim.stepSize

    def gather(self, step: int, released_at: float, nodes: set[str] | None = None,
               paced: bool = True) -> dict[str, float]:
        """Gather the outputs due at point ``step`` (every stepping node's whose step ends there,
        or just ``nodes``'), and a played source's word that its samples for ``step`` are sent
        (unless not ``paced``: the initialisation's answers); return arrival offsets (s), each
        from its node's release."""
        if nodes is not None:
            pending = set(nodes) | (set(self.paced) if paced else set())
        elif self.coupling.multirate:
            pending = self.ledger.due(step) | set(self.paced)
        else:
            pending = set(self._everyone)
        arrivals: dict[str, float] = {}
        for node, frame in self.ledger.kept_for(pending):
            self._take(node, frame, released_at, pending, arrivals)
        deadline = time.monotonic() + self.cosim.stepTimeout
        while pending:
            if self.lost:
                deadline, wait = self._patience(deadline, step)
            else:
                wait = max(deadline - time.monotonic(), 0.0)
            msg = self.inbox.recv(wait)
            if msg is None:
                if self.lost:
                    continue  # _patience reports a node lost too long
                raise RunError(f"timed out after {self.cosim.stepTimeout:g} s at step {step} "
                               f"(t={self._time(step):g} s) waiting for outputs of {', '.join(sorted(pending))}")
            got = self.take_in(msg[0], msg[1], step, True)
            if got is None:
                continue
            node, frame = got
            if frame.kind == frames.END and (self.project.node(node).asynchronous or (
                    frame.step == self.ledger.label(node, step) + 1 and not frame.clean)):
                # A source stopped or failed (never clean: the intake), or a node stopped
                # (SIGTERM) while waiting for a release: it names the next step.
                self._on_end(node, step, frame)
            verdict = self.ledger.sort(node, frame, step, pending)
            if verdict is TAKE:
                self._take(node, frame, released_at, pending, arrivals)
            elif verdict is LATER:
                self.ledger.keep(node, frame)
            elif verdict is ENDED:
                self._on_end(node, step, frame)
                # The others' outputs at the step's end (inside a batch: their batches, which
                # hold the points its earlier steps reached) are gathered before the run ends.
                pending.discard(node)
                self.ledger.earlier[node] = frame.earlier
                arrivals[node] = self.ledger.since_release(node, released_at)
                self.ending.inside.add(node)
                self.ending.arrivals = arrivals
            else:
                self.intake.drop(verdict.reason, verdict.detail, step, node)
        if self.ending.inside:
            raise _ModelEnded
        return arrivals

    def _take(self, node: str, frame: frames.Frame, released_at: float, pending: set[str],
              arrivals: dict[str, float]) -> None:
        pending.discard(node)
        if node not in self.histories:  # a played source's values are its samples'
            self.outputs[node] = frame.values
        if frame.kind == frames.BATCH:
            self.ledger.earlier[node] = frame.earlier
        arrivals[node] = self.ledger.since_release(node, released_at)

    def _patience(self, deadline: float, step: int) -> tuple[float, float]:
        """While a node is away: the deadline of point ``step`` and how long the inbox is waited
        on now. The step's own timeout does not run then (its return, or a restore, gives the
        others a fresh one), and the wait ends with the node's grace, when the run stops naming it."""
        node, since = min(self.lost.items(), key=lambda item: item[1])
        grace = self._grace()
        if time.monotonic() - since > grace:
            raise RunError(f"node {node!r} was lost at step {step} (t={self._time(step):g} s) and did not "
                           f"come back within the link grace of {grace:g} s")
        deadline = max(deadline, time.monotonic() + self.cosim.stepTimeout)
        return deadline, max(min(deadline, since + grace + 0.01) - time.monotonic(), 0.0)

    def _on_end(self, node: str, step: int, frame: frames.Frame) -> None:
        """A node's END instead of its outputs for ``step``: its model ended the run (the caller
        gathers the others' outputs of the release before it ends), or failed."""
        t, clean, message, last = frame.t, frame.clean, frame.message, frame.last
        # The point the run's records end at (inside a batched release: its first, until the
        # points its steps before reached are recorded).
        message, k = message[:_MESSAGE_MAX], self._point
        if not clean:
            # The node's runtime names itself and the step; a message that does not is prefixed.
            # A source lives on the wall clock and knows no step: the run's is added.
            at = f" (the run at step {k}, t={self._time(k):g} s)" if self.project.node(node).asynchronous else ""
            raise RunError(message + at if message.startswith(f"node {node!r}")
                           else f"node {node!r} failed at step {k} (t={self._time(k):g} s): {message}")
        if self.ending.inside:
            return  # another node ended in this release first: the run ends by its word
        self.ending.by = {"node": node, "step": k, "t": t, "message": message}
        self.ending.values = last
        self._log.info("node ended the simulation", node=node, step=k, t=t, message=message)

    def _initialise(self) -> None:
        """The initialisation phase (server.initialisation): each node whose start outputs read
        linked inputs is given them at t0 and answers with its outputs again, in dependency
        order; a loop is swept until its outputs settle, or the run fails naming it."""
        mode, t0, settings = self.coordinator.mode, self.cosim.startTime, self.cosim.initialize
        feedthrough = {n: initialisation.checked_feedthrough(self.capabilities.get(n, {}).get("startFeedthrough"),
                                                             self.project.node(n).input_names(),
                                                             self.project.node(n).output_names())
                       for n in self.stepping}
        groups = initialisation.plan(self.loaded.routes, mode, feedthrough, self.stepping)
        done: list[dict[str, Any]] = []
        self.recorder.meta["initialisation"] = done
        if not groups:
            return
        self.router.route(mode, t0, self.outputs, self.histories)  # the sources' values at t0 too
        names = {n: self.project.node(n).output_names() for n in self.stepping}
        for group in groups:
            for sweep in range(1, (settings.maxIterations if group.loop else 1) + 1):
                before = {n: list(self.outputs[n]) for n in group.nodes}
                for node in group.nodes:
                    self.router.route_into(node, mode, self.outputs)
                    self.release.put(frames.encode(frames.INIT, t0, {node: list(self.router.inputs[node])}))
                    self.messages["releases"] += 1
                    self.gather(0, time.perf_counter(), {node}, paced=False)
                if not group.loop:
                    break
                change = initialisation.residuals(before, self.outputs, names)
                if max(change.values(), default=0.0) <= settings.tolerance:
                    break
            else:
                worst = sorted(change.items(), key=lambda item: -item[1])[:4]
                loop = initialisation.describe_loop(group, self.loaded.routes, feedthrough)
                raise RunError(
                    f"initialisation: the algebraic loop {loop} did not settle in {settings.maxIterations} "
                    "sweeps (coSimulation.initialize.maxIterations); "
                    "its last changes: " + ", ".join(f"{port} {value:.3g}" for port, value in worst)
                    + f" (tolerance {settings.tolerance:g})")
            done.append({"nodes": list(group.nodes), "loop": group.loop, "sweeps": sweep})
            self._log.info("initialised", nodes=list(group.nodes), sweeps=sweep)

    def _localisation_plan(self) -> bool:
        """Whether steps may be rolled back to locate guard crossings; say why not in the metadata."""
        plan = plans.localisation(self.cosim, self._said())
        self.recorder.meta["event_localisation"] = plan.words
        return plan.on

    def _retake_plan(self) -> None:
        """Whether steps are iterated or their size controlled; say which, or why not, in the metadata."""
        meta, cosim = self.recorder.meta, self.cosim
        if cosim.iterate is not None:
            it = cosim.iterate
            plan = plans.iteration(it, self._said(), {n: bool(ports) for n, ports in self._input_labels.items()})
            meta["iteration"] = plan.words
            if not plan.on:
                self._log.warning("no iterative coupling", why=plan.why)
            else:
                self.iteration = IterationLog(it)
                if plan.interpolated:
                    self.track = InputTrack(it.interpolate, list(plan.interpolated))
                    self._short_steps = (it.interpolate - 1) * STARTUP_SPLIT
                elif it.interpolate > 0:
                    self._log.warning("no interpolated inputs", nodes=list(plan.holding))
        if cosim.stepControl is not None:
            plan = plans.step_control(cosim.stepControl, cosim.stepSize, self._said())
            meta["step_control"] = plan.words
            if not plan.on:
                self._log.warning("no step control", why=plan.why)
            else:
                self.sizer = StepSizer.starting(cosim.stepControl, cosim.stepSize)

    def _change(self, mode: str, used: dict[str, list[Any]], tolerance: float) -> tuple[dict[str, list[Any]], float, str, float]:
        """The inputs routed from the outputs now, and their change from ``used`` (input_change)."""
        candidate = self.router.candidate(mode, self.outputs)
        return (candidate, *input_change(candidate, used, self._input_labels, tolerance))

    def _iterated(self, k: int, t: float, h: float, mode: str) -> tuple[dict[str, float], float, int]:
        """Take step k until the inputs routed from its end stop changing; return arrivals, wait
        and takes. The inputs it was last taken on stay in the router (they are point k's record)."""
        it = self.iteration.settings
        track = self.track
        start: dict[str, list[Any]] = {}
        if track is not None:
            # The routed inputs are point k's; the step is taken on its end values (first guessed
            # from the points before), which the interpolating nodes reach along a polynomial.
            track.add(t, mode, self.router.inputs)
            start = track.start()
            self.router.inputs = track.first_guess(t, h)
        arrivals, wait = {}, 0.0

        def retake(inputs: dict[str, list[Any]]) -> None:
            nonlocal arrivals, wait
            self.release.put(frames.encode(frames.ROLLBACK, k, t))
            self.router.inputs = inputs
            arrivals, wait = self._release(k, t, h, mode, **self._moving(start, t, h))

        try:
            arrivals, wait = self._release(k, t, h, mode, **self._moving(start, t, h))
            s = iterate_step(self.router.inputs, lambda used: self._change(mode, used, it.tolerance), retake, it)
        finally:
            for n in track.nodes if track is not None else ():  # point k's record: what each had at t
                self.router.inputs[n] = start[n]
        self.iteration.add(k, t, s.takes, s.change, s.port, s.absolute)
        self.recorder.meta["iterations"] = self.iteration.record()  # in the meta however the run ends
        if not s.converged:
            self._log.warning("step did not converge", step=k, t=t, takes=s.takes, port=s.port, change=s.absolute)
            if it.onFailure == "stop":
                raise RunError(f"step {k} (t={t:g} s) did not converge in {s.takes} takes: input {s.port} still "
                               f"changed by {s.absolute:g} (tolerance {it.tolerance:g}·max(1, |value|))")
        return arrivals, wait, s.takes

    def _moving(self, start: dict[str, list[Any]], t: float, h: float) -> dict[str, Any]:
        """The release's inputs and slopes when inputs are interpolated: an interpolating node
        gets the value at the step's start and the derivatives there; any other the end value."""
        if self.track is None:
            return {}
        end = self.router.inputs
        inputs = {n: start[n] if n in self.track.nodes else end[n] for n in end}
        return {"inputs": inputs, "slopes": self.track.slopes(t, h, end)}

    def _controlled(self, k: int, t: float, h: float, mode: str,
                    record: Callable[[], None]) -> tuple[float, dict[str, float], float, int]:
        """Take step k, shorter again and again while its inputs changed too much over it; return
        the step length that stood, arrivals, wait and takes."""
        tolerance = self.sizer.settings.tolerance
        used = {n: list(v) for n, v in self.router.inputs.items()}
        arrivals, wait = self._release(k, t, h, mode, meanwhile=record)

        def retake(length: float) -> None:
            nonlocal arrivals, wait
            self.release.put(frames.encode(frames.ROLLBACK, k, t))
            arrivals, wait = self._release(k, t, length, mode)

        h, takes = control_step(h, lambda: self._change(mode, used, tolerance)[1], retake, self.sizer)
        self.recorder.meta["step_sizes"] = self.sizer.record()  # in the meta however the run ends
        return h, arrivals, wait, takes

    def _release(self, k: int, t: float, h: float, mode: str,
                 meanwhile: Callable[[], None] | None = None,
                 times: list[float] | None = None, inputs: dict[str, list[Any]] | None = None,
                 slopes: dict[str, Any] | None = None) -> tuple[dict[str, float], float]:
        """Release step k (t → t+h) and gather the outputs due at t+h; return arrivals and wait.

        Jacobi: one release for every node due at k, on the inputs routed at t. Gauss-Seidel:
        one release per node in order, each on inputs routed again from its predecessors'
        outputs at t+h. ``meanwhile`` runs once the (first) release is sent, while the nodes
        integrate: work there (recording the point) is off the barrier's critical path.
        ``times``: a batched release (STEPS) over these base points, gathered at the last.
        ``inputs`` and ``slopes``: the release's, for interpolated inputs (else the router's).
        """
        released_at = time.perf_counter()
        if self.coupling.scheme == "gauss-seidel":
            return self._release_in_order(k, t, h, mode, released_at, meanwhile)
        if self._direct is not None:
            try:
                arrivals = self._call(self.stepping, k, t, h, mode, released_at)
            finally:
                if meanwhile is not None:
                    meanwhile()
            return arrivals, time.perf_counter() - released_at
        due = self.coupling.due(k) if self.coupling.multirate else self.stepping
        try:
            self._put_release(k, t, h, mode, due, released_at, times, inputs, slopes)
        finally:
            if meanwhile is not None:
                meanwhile()  # a release that could not be sent still leaves its point recorded
        arrivals = self.gather(k + 1 if times is None else k + len(times) - 1, released_at)
        return arrivals, time.perf_counter() - released_at

    def _put_release(self, k: int, t: float, h: float, mode: str, nodes: list[str], released_at: float,
                     times: list[float] | None = None, inputs: dict[str, list[Any]] | None = None,
                     slopes: dict[str, Any] | None = None) -> None:
        """Send the release of step k to ``nodes``: each owes its outputs, labelled k + 1, at the
        end of its own step (k + its rate, or the last point). ``times``: a batched release
        over these base points, after which a node as fast as the batch or faster owes its
        outputs (one BATCH, with those of its steps before the last)."""
        inputs = {n: (inputs or self.router.inputs)[n] for n in nodes}
        if times is None:
            self._last_release = frames.encode(frames.STEP, k, t, h, mode, inputs, self.coordinator.driven_nodes(),
                                               slopes or {})
        else:
            self._last_release = frames.encode(frames.STEPS, k, times, mode, inputs, self.coordinator.driven_nodes())
        try:
            self.release.put(self._last_release)
        except FrameTooLarge as exc:
            raise RunError(f"the release of step {k} (t={t:g} s) is {exc}; largest inputs, by node: "
                           f"{frames.largest_values(inputs.items())}") from None
        self.messages["releases"] += 1
        self.ledger.released(nodes, k, released_at, count=1 if times is None else len(times) - 1,
                             batched=times is not None, span=self._span, last_point=self._last_point)
        for n in nodes:
            self._last_release_of[n] = self._last_release

    def _call(self, nodes: list[str], k: int, t: float, h: float, mode: str, released_at: float) -> dict[str, float]:
        """The release of step k to ``nodes`` hosted in process, as calls: each steps on the inputs
        routed for it and returns its outputs at t + h, checked by the intake as an OUTPUTS
        frame's are (Intake.check_direct); return arrival offsets. A node whose model ended
        the run or failed sent its END instead, which is gathered as in a release by frames."""
        direct, inputs, outputs, check = self._direct, self.router.inputs, self.outputs, self.intake.check_direct
        driven = self.coordinator.driven_nodes()
        arrivals: dict[str, float] = {}
        ended = []
        for node in nodes:
            values = direct[node](k, t, h, mode, node in driven, inputs[node])
            if values is None:
                ended.append(node)
                continue
            try:
                check(node, k + 1, t + h, values)
            except Dropped as exc:
                raise RunError(f"node {node!r} gave outputs at step {k + 1} (t={t + h:g} s) the run cannot take: "
                               f"{exc.detail}") from None
            outputs[node] = values
            arrivals[node] = time.perf_counter() - released_at
        self.messages["releases"] += 1
        self.messages["received"] += len(arrivals)
        if ended:
            self.ledger.released(ended, k, released_at)
            try:
                arrivals.update(self.gather(k + 1, released_at, set(ended), paced=False))
            except _ModelEnded:
                self.ending.arrivals.update(arrivals)
                raise
        return arrivals

    def _release_in_order(self, k: int, t: float, h: float, mode: str, released_at: float,
                          meanwhile: Callable[[], None] | None) -> tuple[dict[str, float], float]:
        """Gauss-Seidel: release the nodes one after the other, each on its predecessors' new outputs.
        Each node's inputs are routed again just before its release, and so are, once all are
        released, the inputs every node stepped on."""
        arrivals: dict[str, float] = {}
        try:
            for i, node in enumerate(self.coupling.order):
                if i > 0:
                    self.router.route_into(node, mode, self.outputs)
                if self._direct is not None:
                    arrivals.update(self._call([node], k, t, h, mode, released_at))
                    continue
                self._put_release(k, t, h, mode, [node], time.perf_counter())
                arrivals.update(self.gather(k + 1, released_at, {node}))
        finally:
            if meanwhile is not None:
                meanwhile()
        return arrivals, time.perf_counter() - released_at

    def _record_point(self, p: _Point, seen: _Seen) -> None:
        """Point p as the loop saw it, with the inputs the step from it is taken on (an iterated
        step's last) and how the step to it went; and shown."""
        self._show(p, seen)
        self._row(p.k, p.t, seen.mode, seen.outputs, self.router.inputs, seen.stepped)
        self.recorder.timing(p.k, p.t, p.wait, seen.holder, seen.lateness, p.arrivals, seen.ages, p.takes)

    def _record_inside(self, k: int, times: list[float], mode: str, at_k: dict[str, list[Any]],
                       arrivals: dict[str, float]) -> dict[str, list[Any]]:
        """The base points inside the batched release from point k, each with the outputs every
        node had there (a node's after each of its own steps, held between) and the inputs
        they route to: what a release per base point would have recorded. Their timing: no
        wait of their own (the batch's is at its end), and for each node whose step ended
        there, when the frame with its outputs came. Return the outputs at the last."""
        outputs = dict(at_k)
        holder = max(arrivals, key=arrivals.get) if arrivals else ""
        for i in range(1, len(times) - 1):
            came = {}
            for node, values in self._steps_ending_at(i):
                outputs[node] = values
                came[node] = arrivals[node]
            self.router.route(mode, times[i], outputs, self.histories)
            self._row(k + i, times[i], mode, outputs, self.router.inputs, self.coupling.due(k + i))
            self.recorder.timing(k + i, times[i], 0.0, holder, None, came, {})
        return outputs

    def _record_end(self, k: int, mode: str, at_k: dict[str, list[Any]], times: list[float]) -> None:
        """A node's model ended the run in the release from point k over the base points
        ``times`` ([t, t + h] for one step). Inside a batch, record the points its steps before
        reached (every other node's batch reached them too), as one release per base point
        would have. Then the point where it ended, as FMPy records an FMU that terminates: its
        outputs there; the others' at that point if it is the next one (their outputs for the
        step that ends there came), else held from the last recorded point, as the links hold
        them between points. Nothing is added where the node gave no outputs or ended outside
        the step after the last recorded point (a slower node's)."""
        ended = self.ending.by
        assert ended is not None
        reached, held = 0, at_k
        if len(times) > 2:
            reached = min([len(self.ledger.earlier[n]) * self.coupling.rates[n] for n in self.ending.inside]
                          + [len(times) - 2])
            if reached > 0:
                held = self._record_inside(k, times[:reached + 2], mode, at_k, self.ending.arrivals)
                ended["step"] = k + reached
        tol = 1e-9 * self.cosim.stepSize
        after, t_end = reached + 1, ended["t"]
        if self.ending.values is None or not times[reached] + tol < t_end <= times[after] + tol:
            return
        on_grid = t_end >= times[after] - tol
        outputs = dict(self._outputs_inside(after, times, held) if on_grid else held)
        outputs[ended["node"]] = self.ending.values
        at = times[after] if on_grid else t_end
        self.router.route(mode, at, outputs, self.histories)
        self._row(k + after, at, mode, outputs, self.router.inputs, None)
        self.recorder.timing(k + after, at, 0.0, ended["node"], None, self.ending.arrivals if on_grid else {}, {})
        ended["step"] = k + after

    def _outputs_inside(self, i: int, times: list[float], held: dict[str, list[Any]]) -> dict[str, list[Any]]:
        """Every node's outputs at base point i of the release over ``times`` that ended early
        (``held``: at point i - 1): the release's end is what the nodes answered; inside a
        batch, those of each node whose own step ended there."""
        if i == len(times) - 1:
            return self.outputs
        return {**held, **dict(self._steps_ending_at(i))}

    def _steps_ending_at(self, i: int) -> Iterator[tuple[str, list[Any]]]:
        """Inside the batched release being gathered: each node whose own step ends at base
        point i (a node that ended the run, up to its last step before), and its outputs there."""
        for node, earlier in self.ledger.earlier.items():
            m = self.coupling.rates[node]
            if i % m == 0 and i // m - 1 < len(earlier):
                yield node, earlier[i // m - 1]

    def _localise(self, k: int, t: float, h: float, mode: str, watched_at_start: bool,
                  arrivals: dict[str, float], wait: float) -> tuple[float, dict[str, float], float, dict[str, Any]]:
        """Shrink step k until a guard crossing inside it lies within eventTolerance of its end
        (server.localisation): the step was taken and its end satisfies a guard that did not
        hold at its start. Return the step length that stands, arrivals, wait and the window."""
        view = OutputView(self.router.output_index, self.outputs)
        tol = self.cosim.eventTolerance
        if watched_at_start or not self.coordinator.pending_guard_holds(view) or h <= tol:
            return h, arrivals, wait, {}

        def take(length: float) -> bool:
            nonlocal arrivals, wait
            self.release.put(frames.encode(frames.ROLLBACK, k, t))
            arrivals, wait = self._release(k, t, length, mode)
            return self.coordinator.pending_guard_holds(view)

        at = bisect_crossing(h, tol, take)
        return at.hi, arrivals, wait, {"retries": at.tries, "window": [t + at.lo, t + at.hi]}

    def _begin(self) -> tuple[_Point, dict[str, Any] | None]:
        """START, or resuming, the last checkpoint: the first point, with every stepping node's
        outputs there (and the checkpoint's server state when resuming)."""
        cosim = self.cosim
        rt, wall0 = cosim.real_time_factor(), time.time()
        start = (frames.START, self.recorder.run_dir.name, cosim.startTime, cosim.stepSize, wall0, rt,
                 {"checkpoint": self._saves_states()})
        if self._resume is not None:
            # Every node is a new process: each gets its state at the last checkpoint (the run's
            # START follows, for asynchronous sources, with the clock from there).
            self._start_frame = frames.encode(*start)
            self._checkpoints = cosim.checkpointEvery is not None
            p, resumed = self._restored(_Recover("server", self._resume, "resumed"))
            if self.gateway is not None:
                self.gateway.run_started()
            return p, resumed
        self._last_release = self._start_frame = frames.encode(*start)
        self.release.put(self._last_release)
        released_at = time.perf_counter()
        self._clock = RealTimeClock(cosim.startTime, wall0, rt) if rt is not None else None
        if self.gateway is not None:
            self.gateway.run_started()
        self.ledger.expect_all(0, released_at)
        self._starting = True
        try:
            arrivals = self.gather(0, released_at)
        finally:
            self._starting = False
        if self.scenario:  # what the nodes start on, overrides at t0 included
            self._manipulate(0, cosim.startTime)
        if cosim.initialize.enabled:
            self._initialise()
        self._checkpoint_at = cosim.startTime
        return _Point(0, cosim.startTime, cosim.startTime, 0, {}, arrivals, time.perf_counter() - released_at), None

    def _restored(self, cause: _Recover) -> tuple[_Point, dict[str, Any]]:
        """The run back at its last checkpoint (:meth:`_restore`): the point to go on from, and
        the checkpoint's server state."""
        s, arrivals, wait = self._restore(cause)
        self.scenario.rewind(s["t"])  # its record after the checkpoint was cut with the others
        for observer in self.observers:
            self._tell(observer, "state_restored", s["step"], s["t"])
        if self.sizer is not None:
            self.sizer.h = s["h"]
        self._checkpoint_at = self._next_checkpoint(s["t"])
        rt = self.cosim.real_time_factor()
        self._clock = RealTimeClock(s["t"], time.time(), rt) if rt is not None else None
        return _Point(s["step"], s["t"], s["origin"], s["j"], dict(s["localised"]), arrivals, wait), s

    def _plan(self, resumed: dict[str, Any] | None) -> None:
        """Once the nodes said what they can: localisation, retakes, batching and checkpoints."""
        cosim = self.cosim
        self._localising = self._localisation_plan()
        self._retake_plan()
        if resumed is not None:
            self._restore_track(resumed, f"the checkpoint at step {resumed['step']} resumed")
            if self.sizer is not None:
                self.sizer.h = resumed["h"]
        # A bridge FMU through the gateway takes one release at a time (its node says no HELLO).
        cannot = [n for n in self.stepping if self.capabilities.get(n, {}).get("batches") is not True]
        self._span = 1 if cannot else self.coupling.batch
        self.recorder.meta["coupling"] = self.coupling.describe(cannot if self.coupling.batch > 1 else None)
        self._checkpoints = self._checkpoint_plan()
        self._last_point = math.ceil((cosim.stopTime - cosim.startTime) / cosim.stepSize - 1e-9)
        direct = plans.direct_steps(self.stepping, self.transport.direct, multirate=self.coupling.multirate,
                                    played=bool(self.paced), checkpoints=self._checkpoints,
                                    interpolated=self.track is not None)
        self.recorder.meta["releases"] = direct.words
        self._direct = self.transport.direct if direct.on else None

    def _arrive(self, p: _Point, final: bool) -> _Seen:
        """Point p before the step from it (``final``: at stopTime): a checkpoint when one is
        due, the sources' values held, the guards (maybe a mode switch), the inputs routed, the
        pace of a real-time run. What the release needs, and nothing else: the point is shown
        with its record (:meth:`_record_point`), once the release is sent."""
        H = self.cosim.stepSize
        # A multi-rate run's checkpoints wait for a point where no node is inside its step.
        if self._checkpoints and self._checkpoint_at - 1e-9 * H <= p.t and not final and p.k % self.coupling.period == 0:
            self._take_checkpoint(p.k, p.t, p.origin, p.j, p.localised, self.sizer.h if self.sizer else H)
            self._checkpoint_at = self._next_checkpoint(p.t)
        for node, history in self.histories.items():
            held = history.at(p.t)
            if held is not None:
                self.outputs[node] = held[1]
        view = OutputView(self.router.output_index, self.outputs)
        self._switch(p, view)
        mode = self.coordinator.mode
        if self.scenario:
            self._manipulate(p.k, p.t)
        ages = self.router.route(mode, p.t, self.outputs, self.histories)
        lateness = self._pace(p.t)
        holder = max(p.arrivals, key=p.arrivals.get) if p.arrivals else ""
        stepped = self.coupling.due(p.k) if self.coupling.multirate and not final else None
        # The outputs kept: the step replaces them before point p is recorded.
        return _Seen(mode, dict(self.outputs), view, ages, lateness, holder, stepped)

    def _manipulate(self, k: int, t: float) -> None:
        """The scenario's overrides in force at point k, and the record of those taking effect there."""
        self.router.pins = self.scenario.pins_at(t)
        for entry in self.scenario.taking_effect(k, t):
            self.recorder.event(entry)
            self._log.info("scenario", step=k, **{key: v for key, v in entry.items() if key not in ("step",)})

    def apply_scenario(self, k: int, t: float) -> None:
        """A caller changed the scenario while the loop stands at point k (through a PointGate):
        the inputs routed there take it, so the step from k is taken on them."""
        self._manipulate(k, t)
        self.router.route(self.coordinator.mode, t, self.outputs, self.histories)  # as the point routed them

    def add_observer(self, observer: Observer) -> None:
        """Tell ``observer`` of every point recorded from now on, of rollbacks and of the end
        (in the loop's thread: add one while the loop stands at a point, or before it runs)."""
        self.observers.append(observer)
        self._row = self._row_observed

    def _row_observed(self, step: int, t: float, mode: str, outputs: dict[str, list[Any]],
                      inputs: dict[str, list[Any]], stepped: list[str] | None = None) -> None:
        self.recorder.row(step, t, mode, outputs, inputs, stepped)
        values = self._values.at(outputs, inputs)
        for observer in self.observers:
            self._tell(observer, "step_complete", step, t, values)

    def _tell(self, observer: Observer, what: str, *args: Any) -> None:
        try:
            getattr(observer, what)(*args)
        except Exception as exc:  # a user's observer: its failure ends the run, named, records kept
            raise RunError(f"observer {type(observer).__name__}: {what} failed at step {self._point}: "
                           f"{type(exc).__name__}: {exc}") from exc

    def _switch(self, p: _Point, view: OutputView) -> None:
        """Evaluate the guards at point p; a switch of mode is recorded (with the located event
        that ended the step to p) and logged."""
        try:
            switch = self.coordinator.update(p.k, p.t, view)
        except GuardEvaluationError as exc:
            raise RunError(f"{exc} (at step {p.k}, t={p.t:g} s)") from None
        if switch is None:
            return
        entry = switch.as_record()
        if p.localised:
            entry["localised"] = p.localised
        self.recorder.event(entry)
        self.latest.switches.append(entry)
        self._log.info("mode switch", step=p.k, t=p.t, name=switch.event, to=switch.to_mode, values=switch.values)

    def _pace(self, t: float) -> float | None:
        """A real-time run waits for t on the wall clock; return how late it is there (None: unpaced)."""
        if self._clock is None:
            return None
        ahead = self._clock.seconds_until(t)  # read once: a second reading may have passed t
        if ahead > 0:
            time.sleep(ahead)
        return max(0.0, -ahead)

    def _show(self, p: _Point, seen: _Seen) -> None:
        """Point p for the progress bar and the status answer."""
        self.progress.step, self.progress.t, self.progress.mode = p.k, p.t, seen.mode
        self.progress.lateness_s = seen.lateness
        now = time.perf_counter()
        if self.transport.serves_status:  # in process nobody asks: a fifth of a step's work saved
            self.latest.point((now, seen.holder, p.wait, p.arrivals), p.k, p.t, seen.mode, seen.outputs,
                              self.router.inputs, seen.ages)
        self._rate.point(self.progress, p.k, now)

    def _next_point(self, p: _Point, short: bool) -> tuple[float, list[float] | None]:
        """The time the step from point p ends, and for a batched release the base points it spans."""
        cosim = self.cosim
        H = cosim.stepSize
        if short:  # interpolated inputs' start-up: steps of H / STARTUP_SPLIT until there are points enough
            return min(cosim.startTime + (p.k + 1) * H / STARTUP_SPLIT, cosim.stopTime), None
        if self.sizer is not None:
            return min(p.t + self.sizer.h, cosim.stopTime), None
        if self._span > 1:  # a batched release: its base points as single releases would have them
            times = [min(p.origin + (p.j + i) * H, cosim.stopTime)
                     for i in range(min(self._span, self._last_point - p.k) + 1)]
            return times[-1], times
        return min(p.origin + (p.j + 1) * H, cosim.stopTime), None

    def _step_from(self, p: _Point, seen: _Seen) -> _Point:
        """Take the step from point p by the run's strategy (iterated, size-controlled or plain,
        then located if a guard crossed inside it) and return the point it ends at. Point p is
        recorded while the nodes take its step."""
        record = functools.partial(self._record_point, p, seen)
        short = p.k < self._short_steps
        next_t, times = self._next_point(p, short)
        h = h_used = next_t - p.t
        watched = self._localising and self.coordinator.pending_guard_holds(seen.view)
        takes = 1
        try:
            if self.iteration is not None:
                try:
                    arrivals, wait, takes = self._iterated(p.k, p.t, h, seen.mode)
                finally:
                    record()  # also when the step failed: point p stands
            elif self.sizer is not None:
                h_used, arrivals, wait, takes = self._controlled(p.k, p.t, h, seen.mode, record)
            else:
                arrivals, wait = self._release(p.k, p.t, h, seen.mode, meanwhile=record, times=times)
                if times is not None:
                    self._record_inside(p.k, times, seen.mode, seen.outputs, arrivals)
            localised: dict[str, Any] = {}
            if self._localising:
                h_used, arrivals, wait, localised = self._localise(p.k, p.t, h, seen.mode, watched, arrivals, wait)
        except _ModelEnded:
            self._record_end(p.k, seen.mode, seen.outputs, times or [p.t, next_t])
            raise
        origin, j = p.origin, p.j
        if h_used != h:  # a located event, or a controlled step taken shorter: a new grid from there
            origin, j, next_t = p.t + h_used, -1, p.t + h_used
        elif short:  # the grid of H starts where the short steps end
            origin, j = next_t, -1
        count = 1 if times is None else len(times) - 1
        return _Point(p.k + count, next_t, origin, j + count, localised, arrivals, wait, takes)

    def _loop(self) -> None:
        p, resumed = self._begin()
        self._plan(resumed)
        end = self.cosim.stopTime - 1e-9 * self.cosim.stepSize
        self._rate.begin(p.k)
        while True:
            self._point = p.k
            seen = self._arrive(p, p.t >= end)
            if p.t < end:
                self._gate.hold(p.k, p.t)  # the step from p waits for a caller's word; a stop may come meanwhile
            if p.t >= end or self._stop_requested.is_set():
                self._record_point(p, seen)
                break
            try:
                p = self._step_from(p, seen)
            except _ModelEnded:
                break
            except _Recover as cause:  # back to the last checkpoint: its point is taken again, as it was
                p, _ = self._restored(cause)
        self.recorder.meta["steps_per_s"] = self._rate.end(self.progress, p.k)
