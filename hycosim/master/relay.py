"""The relay server's co-simulation loop: attach, then the macro-step barrier until stopTime.

Read top to bottom, :meth:`Relay.run` and :meth:`Relay._loop` are the whole algorithm:

1. wait until every node holds a liveliness token (attachTimeout names the missing ones);
2. :meth:`_begin`: START, every stepping node reports its outputs at t0 (then the
   initialisation phase), or, resuming, every node gets its state at the last checkpoint;
   :meth:`_plan`: what the nodes said they can take part in (the algorithm that runs,
   batches, checkpoints, and whether the run is plain);
3. at each macro-step point (:meth:`_points`), :meth:`_arrive`: a checkpoint if one is due,
   the guards (maybe a mode switch), the outputs routed along the links active in the mode,
   pacing; then :meth:`_step_from`: the master algorithm (master.algorithms: Jacobi,
   Gauss-Seidel, iterated, step-controlled, localised, or a user's) takes the step
   T_k → T_k+H over the barrier (master.barrier: releases out, answers in), point k recorded
   while the nodes step. A plain run (routing and releases only) takes its points the same
   way in one flat loop (plain_loop.py);
4. STOP at stopTime, on Ctrl-C, or on a fault, with everything recorded so far on disk.

The parts beside it: who is attached (membership.py), checkpoints (checkpointing.py), the
records and observers of each point (point_records.py). The transport (Zenoh sessions and
keys, or calls in one process) is given as a :class:`~hycosim.transport.server_side.Transport`;
the loop does not know which (only the gateway for bridge FMUs asks for its Zenoh session).
"""

from __future__ import annotations

import math
import os
import threading
import time
from typing import Any

import structlog

from hycosim.bridge.gateway import Gateway, GatewayError
from hycosim.core import frames, signals
from hycosim.core.config import LoadedProject
from hycosim.core.schema import ScenarioAction
from hycosim.core.sim_clock import RealTimeClock
from hycosim.master import initialisation, plans
from hycosim.master.algorithms.choice import project_algorithm
from hycosim.master.algorithms.interface import AlgorithmError, MasterAlgorithm, StepRequest
from hycosim.master.algorithms.jacobi import Jacobi
from hycosim.master.barrier import Barrier
from hycosim.master.checkpointing import Checkpointing
from hycosim.master.coordinator import Coordinator, GuardEvaluationError
from hycosim.master.interpolation import STARTUP_SPLIT
from hycosim.master.membership import Membership
from hycosim.master.observers import Observer
from hycosim.master.plain_loop import PlainLoop, plain_plan
from hycosim.master.point_records import PointRecords
from hycosim.master.recorder import Recorder, RecordError
from hycosim.master.routing import OutputView, Router
from hycosim.master.run_state import (OPEN, RECENT_KEPT, ModelEnded, Point, PointGate, Progress, Rate, Recover,
                                      RunError, Seen)
from hycosim.master.scenario import Scenario
from hycosim.master.status_view import LatestPoints
from hycosim.transport.answer_budget import AnswerBudget
from hycosim.transport.keys import ProjectKeys
from hycosim.transport.server_side import Transport

__all__ = ["PointGate", "Progress", "Relay", "RunError"]


class Relay:
    """One run's master: the loop over macro-step points, the barrier and the parts beside it."""

    def __init__(self, loaded: LoadedProject, transport: Transport, recorder: Recorder,
                 progress_every_s: float = 0.0, on_progress: Any = None,
                 gateway_address: tuple[str, int] | None = None, gateway_required: bool = False,
                 resume: int | None = None, gate: PointGate | None = None,
                 scenario: list[ScenarioAction] | None = None, algorithm: MasterAlgorithm | None = None):
        self.loaded, self.project, self.cosim = loaded, loaded.project, loaded.project.coSimulation
        # Who decides when the step from each point is taken: at once, or a Python caller
        # driving the run (hycosim.open), which may look at the point meanwhile.
        self._gate: PointGate = gate or OPEN
        self.transport, self.recorder = transport, recorder
        self._log = structlog.get_logger("server").bind(project=self.project.projectName)
        self.coordinator = Coordinator(self.project.events, loaded.guards)
        self.router = Router(loaded)
        # Overrides of inputs in time (the project's scenario, --scenario, a Python caller's).
        self.scenario = Scenario(self.project, loaded.routes, [*self.project.scenario, *(scenario or [])])
        self.progress = Progress()
        self.members = Membership(self.project, recorder.meta, self._log)
        stepping = [n.nodeName for n in self.project.stepping_nodes()]
        self.checkpointing = Checkpointing(loaded, recorder, stepping, self._log)
        self.barrier = Barrier(loaded, self.router, self.coordinator, recorder, self.members, self.checkpointing,
                               self.progress, self._log)
        self.latest = LatestPoints(self.project, RECENT_KEPT)  # for the status answers
        # The master's own observers of the points: the recorder, and the status answer where
        # anyone can ask for it (in process nobody does: a fifth of a step's work saved).
        self.records = PointRecords(self.project, self.barrier,
                                    [recorder, self.latest] if transport.serves_status else [recorder])
        # How each step is taken; made where the project is loaded, planned once the nodes said what they can.
        self.algorithm: MasterAlgorithm = algorithm if algorithm is not None else project_algorithm(loaded)
        self._short_steps = 0  # steps of H / STARTUP_SPLIT that open the run (interpolated inputs)
        self._plain: PlainLoop | None = None  # the points of a plain run, flat (planned in _plan)
        # The tunable parameters' values as the nodes hold them (None: their start values; {}:
        # unknown, after a restore: every tuned one is sent again).
        self._tuned: dict[tuple[str, str], Any] | None = None
        self.answers = AnswerBudget()  # status answers a second: anyone may ask
        # Go on from the run directory's last checkpoint (its server died after recording this many steps).
        self._resume = resume
        self._rate = Rate(progress_every_s, on_progress)
        self._clock: RealTimeClock | None = None  # a real-time run's (coSimulation.realTimeFactor)
        self._stop_requested = threading.Event()
        self._gateway_address, self._gateway_required = gateway_address, gateway_required
        self.gateway: Gateway | None = None

    # --- what others read ---------------------------------------------------------

    @property
    def outputs(self) -> dict[str, list[Any]]:
        """Every node's latest outputs (a source's as held at the current point)."""
        return self.barrier.outputs

    def _dropped(self) -> dict[str, int]:
        """What was dropped, by reason: the frames the intake refused, the status questions over budget."""
        refused = self.answers.refused
        return {**self.barrier.intake.dropped, **({"status over budget": refused} if refused else {})}

    def status(self, since: int | None = None) -> dict[str, Any]:
        """Who is attached and where the run is, for ``hycosim status`` and the dashboard (read
        from Zenoh's thread: copies of what the loop changes, each taken at once under the GIL).
        ``since``: also the recent points after that step (master.status_view)."""
        restarts: dict[str, int] = {}
        for r in list(self.checkpointing.recoveries):
            restarts[r["node"]] = restarts.get(r["node"], 0) + 1
        nodes = []
        for n in self.project.nodeLists:
            host = self.members.capabilities.get(n.nodeName, {}).get("host")
            nodes.append({"name": n.nodeName, "uid": n.UID, "async": n.asynchronous,
                          "input": n.input_names(), "output": n.output_names(),
                          "host": host if type(host) is str else None, "restarts": restarts.get(n.nodeName, 0)})
        return {"project": self.project.projectName, "attached": sorted(self.members.alive),
                "lost": sorted(self.members.lost), "expected": [n.nodeName for n in self.project.nodeLists],
                "nodes": nodes, "run": self.recorder.run_dir.name, "stopTime": self.cosim.stopTime,
                "lateness_s": self.progress.lateness_s, "dropped": self._dropped(),
                **self.latest.answer(time.perf_counter(), since)}

    @property
    def stopped(self) -> bool:
        """Whether the run was asked to stop before its stop time (a run driven from Python, closed)."""
        return self._stop_requested.is_set()

    def request_stop(self) -> None:
        """Ask the loop to stop at the next macro-step point (thread-safe)."""
        self._stop_requested.set()

    def add_observer(self, observer: Observer) -> None:
        """Tell ``observer`` of every point recorded from now on, of rollbacks and of the end
        (in the loop's thread: add one while the loop stands at a point, or before it runs)."""
        self.records.add_observer(observer)

    def apply_scenario(self, k: int, t: float) -> None:
        """A caller changed the scenario while the loop stands at point k (through a PointGate):
        the inputs routed there take it, so the step from k is taken on them."""
        self._manipulate(k, t)
        self.router.route(self.coordinator.mode, t, self.barrier.outputs, self.barrier.histories)

    # --- the run ------------------------------------------------------------------

    def run(self) -> None:
        """Run the co-simulation: open the transport, wait for the nodes, start them, take the points to
        the stop time (or a stop, a failure, a node's end) and stop them; the records written and
        ``meta.json`` said however it ends."""
        b = self.barrier
        polls = self.project.polls_before_blocking(os.cpu_count())
        self.recorder.meta["server_polls"] = polls
        b.connect(*self.transport.open(ProjectKeys(self.project.projectName), polls, self.cosim.lowLatency,
                                       self.status, self.answers))
        status_text, reason = "failed", ""
        signals.stop_once()
        try:
            self._start_gateway()
            b.wait_for_nodes()
            try:
                self._loop()
            except ModelEnded:  # at the START: no macro step was taken
                pass
            status_text = frames.STOP_COMPLETED if not self._stop_requested.is_set() else frames.STOP_STOPPED
            if b.ending.by is not None:
                self.recorder.meta["ended_by"] = b.ending.by
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
            b.broadcast_stop(status_text if not reason else reason, self.progress.step)
            b.await_departures()
            if self.gateway is not None:
                self.gateway.close(reason or status_text)
            b.intake.drops.flush(self.progress.step)
            self.recorder.meta.update(reason=reason, dropped_frames=self._dropped(),
                                      non_finite=b.intake.non_finite,
                                      reattached=dict(self.members.reattached), server_waits=b.inbox.waits,
                                      messages=dict(b.messages), checkpoints_taken=self.checkpointing.taken,
                                      samples_received={n: h.received for n, h in b.histories.items()})
            self.records.ended(status_text, self._log)  # the recorder first: it writes the outcome
            self.transport.close()
            b.inbox.close()

    def _start_gateway(self) -> None:
        if self._gateway_address is None:
            return
        host, port = self._gateway_address
        try:
            self.gateway = Gateway(
                self.project.stepping_nodes(), self.transport.session, ProjectKeys(self.project.projectName),
                host, port, drop=self.barrier.intake.drop, rates=self.loaded.coupling.rates,
                stop_time=self.cosim.stopTime)
        except GatewayError as exc:
            if self._gateway_required:
                raise RunError(str(exc)) from None
            self._log.warning("gateway disabled", reason=str(exc))
            self.recorder.meta["gateway"] = f"disabled: {exc}"
            return
        self.recorder.meta["gateway"] = self.gateway.address

    def _loop(self) -> None:
        p, resumed = self._begin()
        self._plan(resumed)
        end = self.cosim.stopTime - 1e-9 * self.cosim.stepSize
        self._rate.begin(p.k)
        points = self._plain.run if self._plain is not None else self._points
        while True:
            try:
                points(p, end)
                break
            except ModelEnded:
                break
            except Recover as cause:  # back to the last checkpoint: its point is taken again, as it was
                p, _ = self._restored(cause)
        # The last point recorded: where the run ended (stopTime, a stop, a node's model's end).
        self.recorder.meta["steps_per_s"] = self._rate.end(self.progress, self.progress.step)

    def _points(self, p: Point, end: float) -> Point:
        """From point p on, each point arrived at and the step from it taken by the algorithm,
        until the point at ``end`` (stopTime) or a stop: return that point, recorded."""
        while True:
            self.barrier.point = p.k
            seen = self._arrive(p, p.t >= end)
            if p.t < end:
                self._gate.hold(p.k, p.t)  # the step from p waits for a caller's word; a stop may come meanwhile
            if p.t >= end or self._stop_requested.is_set():
                self._record_point(p, seen)
                return p
            p = self._step_from(p, seen)

    # --- the start and the plan -----------------------------------------------------

    def _saves_states(self) -> bool:
        """Whether nodes save their state before each step, so that a step can be taken again
        (a user's algorithm may roll steps back)."""
        cosim = self.cosim
        return (cosim.eventTolerance is not None or cosim.iterate is not None or cosim.stepControl is not None
                or cosim.algorithm is not None)

    def _begin(self) -> tuple[Point, dict[str, Any] | None]:
        """START, or resuming, the last checkpoint: the first point, with every stepping node's
        outputs there (and the checkpoint's server state when resuming)."""
        cosim, b = self.cosim, self.barrier
        rt, wall0 = cosim.real_time_factor(), time.time()
        start = (frames.START, self.recorder.run_dir.name, cosim.startTime, cosim.stepSize, wall0, rt,
                 {"checkpoint": self._saves_states()})
        if self._resume is not None:
            # Every node is a new process: each gets its state at the last checkpoint (the run's
            # START follows, for asynchronous sources, with the clock from there).
            b.sent.start = frames.encode(*start)
            self.checkpointing.on = self.members.checkpoints = cosim.checkpointEvery is not None
            p, resumed = self._restored(Recover("server", self._resume, "resumed"))
            if self.gateway is not None:
                self.gateway.run_started()
            return p, resumed
        b.sent.last = b.sent.start = frames.encode(*start)
        b.release.put(b.sent.last)
        released_at = time.perf_counter()
        self._clock = RealTimeClock(cosim.startTime, wall0, rt) if rt is not None else None
        if self.gateway is not None:
            self.gateway.run_started()
        b.ledger.expect_all(0, released_at)
        self.members.starting = True
        try:
            arrivals = b.gather(0, released_at)
        finally:
            self.members.starting = False
        if self.scenario:  # what the nodes start on, overrides at t0 included
            self._manipulate(0, cosim.startTime)
        if cosim.initialize.enabled:
            initialisation.run(b, self.loaded, self.coordinator.mode)
        self.checkpointing.at = cosim.startTime
        return Point(0, cosim.startTime, cosim.startTime, 0, {}, arrivals, time.perf_counter() - released_at), None

    def _plan(self, resumed: dict[str, Any] | None) -> None:
        """Once the nodes said what they can: the algorithm that runs, batching and checkpoints."""
        cosim, b = self.cosim, self.barrier
        said = self.members.said(b.stepping)
        self.algorithm = self.algorithm.plan(said, b)
        self._short_steps = self.algorithm.startup_steps()
        if resumed is not None:
            self._restore_algorithm(resumed, f"the checkpoint at step {resumed['step']} resumed")

        # A bridge FMU through the gateway takes one release at a time (its node says no HELLO).
        coupling = self.loaded.coupling
        cannot = [n for n in b.stepping if self.members.capabilities.get(n, {}).get("batches") is not True]
        b.span = 1 if cannot else coupling.batch
        self.recorder.meta["coupling"] = coupling.describe(cannot if coupling.batch > 1 else None)
        self.members.checkpoints = self.checkpointing.plan(said)
        b.last_point = math.ceil((cosim.stopTime - cosim.startTime) / cosim.stepSize - 1e-9)
        direct = plans.direct_steps(b.stepping, self.transport.direct, multirate=coupling.multirate,
                                    played=bool(b.paced), checkpoints=self.checkpointing.on,
                                    algorithm=self.algorithm.frames_only())
        self.recorder.meta["releases"] = direct.words
        b.direct = self.transport.direct if direct.on else None
        plain = plain_plan(
            scheme="" if type(self.algorithm) is Jacobi else type(self.algorithm).__name__,
            events=bool(self.project.events), scenario=bool(self.scenario), sources=bool(b.histories or b.paced),
            checkpoints=self.checkpointing.on, multirate=coupling.multirate, span=b.span, calls=direct.on,
            paced=self.cosim.real_time_factor() is not None, held=self._gate is not OPEN)
        self.recorder.meta["points"] = plain.words
        self._plain = PlainLoop(b, self.records, self.progress, self._rate, self._stop_requested,
                                self.coordinator.mode) if plain.on else None

    def _restore_algorithm(self, s: dict[str, Any], what: str) -> None:
        try:
            self.algorithm.restore(s["algorithm"], self.barrier, what)
        except ValueError as exc:
            raise RunError(str(exc)) from None

    # --- checkpoints ----------------------------------------------------------------

    def _take_checkpoint(self, p: Point) -> None:
        """Ask every stepping node for its state at point p (they send it after their next
        outputs) and keep the server's own, records included, until theirs are in."""
        b = self.barrier
        server = {"step": p.k, "t": float(p.t), "origin": float(p.origin), "j": p.j, "mode": self.coordinator.mode,
                  "disarmed": sorted(self.coordinator.disarmed),
                  "outputs": {n: list(v) for n, v in b.outputs.items()},
                  "inputs": {n: list(v) for n, v in self.router.inputs.items()},
                  "histories": {n: h.snapshot() for n, h in b.histories.items()},
                  "records": self.recorder.positions(p.k), "localised": p.localised,
                  "h": float(self.algorithm.step_length() or self.cosim.stepSize),
                  "algorithm": self.algorithm.checkpoint()}
        b.release.put(self.checkpointing.ask(p.k, server))

    def _restore(self, cause: Recover) -> tuple[dict[str, Any], dict[str, float], float]:
        """Take the whole run back to its last readable checkpoint: every stepping node gets its
        state back and answers with its outputs there, the records are cut back to it, and the
        server takes its own state back. Return the server's state, arrivals and wait."""
        b, began = self.barrier, time.monotonic()
        while True:
            cp = self.checkpointing.latest(cause)
            self.members.restoring = True
            try:
                self.members.fresh.update(b.stepping)
                for frame in self.checkpointing.restore_frames(cp, b.paced, self._saves_states()):
                    b.release.put(frame)
                if cause.node == "server" and b.sent.start is not None:
                    start = frames.decode(b.sent.start)._replace(t0=cp.server["t"])
                    b.sent.start = frames.encode(frames.START, *start)
                    b.release.put(b.sent.start)
                released = time.perf_counter()
                b.ledger.expect_all(cp.step, released)
                arrivals = b.gather(cp.step, released)
                wait = time.perf_counter() - released
            except Recover as again:  # another process restarted meanwhile: once more
                cause = again
                continue
            finally:
                self.members.restoring = False
            break
        restored = self._apply(cp)
        self.checkpointing.note_recovery({
            "node": cause.node, "step": cause.step, "t": self.members.time_of(cause.step), "cause": cause.cause,
            "restored": cp.step, "restored_t": cp.server["t"],
            "seconds": round(time.monotonic() - self.members.went.get(cause.node, began), 3), "at": time.time()})
        return restored, arrivals, wait

    def _apply(self, cp: Any) -> dict[str, Any]:
        """The server's own state at the checkpoint (read as fitting the project), and its
        records cut back to it."""
        s, b = cp.server, self.barrier
        for node, values in b.outputs.items():
            if not self.project.node(node).asynchronous and values != s["outputs"][node]:
                self._log.warning("restored outputs differ from the checkpoint's", node=node, step=cp.step)
        self._restore_algorithm(s, f"checkpoint {cp.path}")
        self.coordinator.mode = s["mode"]
        self.coordinator.disarmed = set(s["disarmed"])
        for node in b.outputs:
            b.outputs[node] = list(s["outputs"][node])
            self.router.inputs[node][:] = s["inputs"][node]
        self.recorder.going_back(s["step"], s["records"])
        self.records.restored(s["step"], s["t"])  # the recorder's files cut back first, then the others told
        for node, history in b.histories.items():
            newer = [(t, v) for t, v in history.snapshot()["samples"]]
            history.restore(s["histories"].get(node, {"samples": [], "received": 0}))
            for t, v in newer:  # samples taken since keep their place: a source is not rolled back
                if history.add(t, v):
                    self.recorder.sample(node, s["step"], t, v)  # as if received again at the checkpoint
        return s

    def _restored(self, cause: Recover) -> tuple[Point, dict[str, Any]]:
        """The run back at its last checkpoint (:meth:`_restore`): the point to go on from, and
        the checkpoint's server state."""
        s, arrivals, wait = self._restore(cause)
        self.scenario.rewind(s["t"])  # its record after the checkpoint was cut with the others
        self._tuned = {}  # what the nodes hold now is not known: every tuned parameter is sent again
        self.checkpointing.go_on_from(s["t"])
        rt = self.cosim.real_time_factor()
        self._clock = RealTimeClock(s["t"], time.time(), rt) if rt is not None else None
        return Point(s["step"], s["t"], s["origin"], s["j"], dict(s["localised"]), arrivals, wait), s

    # --- each point -----------------------------------------------------------------

    def _arrive(self, p: Point, final: bool) -> Seen:
        """Point p before the step from it (``final``: at stopTime): a checkpoint when one is
        due, the sources' values held, the guards (maybe a mode switch), the inputs routed, the
        pace of a real-time run. What the release needs, and nothing else: the point is shown
        with its record (:meth:`_record_point`), once the release is sent."""
        b, coupling = self.barrier, self.loaded.coupling
        if self.checkpointing.on and self.checkpointing.due(p.k, p.t, final, coupling.period):
            self._take_checkpoint(p)
        for node, history in b.histories.items():
            held = history.at(p.t)
            if held is not None:
                b.outputs[node] = held[1]
        view = OutputView(self.router.output_index, b.outputs)
        self._switch(p, view)
        mode = self.coordinator.mode
        if self.scenario:
            self._manipulate(p.k, p.t)
        ages = self.router.route(mode, p.t, b.outputs, b.histories)
        lateness = self._pace(p.t)
        holder = max(p.arrivals, key=p.arrivals.get) if p.arrivals else ""
        stepped = coupling.due(p.k) if coupling.multirate and not final else None
        # The outputs kept: the step replaces them before point p is recorded.
        return Seen(mode, dict(b.outputs), view, ages, lateness, holder, stepped)

    def _manipulate(self, k: int, t: float) -> None:
        """The scenario's overrides in force at point k, and the record of those taking effect
        there; the parameters in force there sent to the nodes whose values differ."""
        self.router.pins = self.scenario.pins_at(t)
        for entry in self.scenario.taking_effect(k, t):
            self.recorder.event(entry)
            self._log.info("scenario", step=k, **{key: v for key, v in entry.items() if key not in ("step",)})
        if self.scenario.tuned:
            self._tune(k, t)

    def tunable(self) -> dict[str, dict[str, Any]]:
        """Each node's tunable parameters and their start values, as its HELLO said."""
        return self.members.tunable()

    def _tune(self, k: int, t: float) -> None:
        """Send each node the tuned parameters whose value in force at point k is not the one it
        holds, before the release of step k (at the first point: every action checked first)."""
        start = self.members.tunable()
        if self._tuned is None and (problem := self.scenario.parameter_problem(start)) is not None:
            raise RunError(problem)  # at the run's first point: before any step
        changed, self._tuned = self.scenario.tunes(t, start, self._tuned)
        for node, values in changed.items():
            self.barrier.release.put(frames.encode(frames.TUNE, node, k, float(t), values))
            self._log.info("parameters", node=node, step=k, values=values)

    def _switch(self, p: Point, view: OutputView) -> None:
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

    def _record_point(self, p: Point, seen: Seen) -> None:
        """Point p as the loop saw it, recorded and shown (the progress bar, the status answer)."""
        self.progress.step, self.progress.t, self.progress.mode = p.k, p.t, seen.mode
        self.progress.lateness_s = seen.lateness
        now = time.perf_counter()
        self._rate.point(self.progress, p.k, now)
        self.records.point(p, seen, now)

    def _next_point(self, p: Point, short: bool) -> tuple[float, list[float] | None]:
        """The time the step from point p ends, and for a batched release the base points it spans."""
        cosim, span = self.cosim, self.barrier.span
        H = cosim.stepSize
        if short:  # interpolated inputs' start-up: steps of H / STARTUP_SPLIT until there are points enough
            return min(cosim.startTime + (p.k + 1) * H / STARTUP_SPLIT, cosim.stopTime), None
        length = self.algorithm.step_length()
        if length is not None:
            return min(p.t + length, cosim.stopTime), None
        if span > 1:  # a batched release: its base points as single releases would have them
            times = [min(p.origin + (p.j + i) * H, cosim.stopTime)
                     for i in range(min(span, self.barrier.last_point - p.k) + 1)]
            return times[-1], times
        return min(p.origin + (p.j + 1) * H, cosim.stopTime), None

    def _step_from(self, p: Point, seen: Seen) -> Point:
        """The algorithm takes the step from point p and the point it ends at is returned.
        Point p is recorded while the nodes take its step."""
        short = p.k < self._short_steps
        next_t, times = self._next_point(p, short)
        h = next_t - p.t
        recorded = False

        def record() -> None:
            nonlocal recorded
            if not recorded:
                recorded = True
                self._record_point(p, seen)

        try:
            taken = self.algorithm.step(self.barrier, StepRequest(p.k, p.t, h, seen.mode, record, times))
        except ModelEnded:
            record()
            self.records.end(p.k, seen.mode, seen.outputs, times or [p.t, next_t])
            raise
        except AlgorithmError as exc:
            raise RunError(str(exc)) from None
        except (RunError, RecordError, Recover):
            raise
        except Exception as exc:
            if self.cosim.algorithm is None:
                raise  # a fault of hycosim's own: an internal error, its traceback in the log
            # A user's algorithm may fail in any way: named, its traceback in the log.
            self._log.exception("master algorithm failed", step=p.k)
            raise RunError(f"master algorithm {type(self.algorithm).__name__} failed at step {p.k} (t={p.t:g} s): "
                           f"{type(exc).__name__}: {exc}") from exc
        finally:
            record()  # one that did not record point p, or failed before it did: recorded here
        if times is not None:
            self.records.inside(p.k, times, seen.mode, seen.outputs, taken.arrivals)
        origin, j = p.origin, p.j
        if taken.h != h:  # a located event, or a controlled step taken shorter: a new grid from there
            origin, j, next_t = p.t + taken.h, -1, p.t + taken.h
        elif short:  # the grid of H starts where the short steps end
            origin, j = next_t, -1
        count = 1 if times is None else len(times) - 1
        return Point(p.k + count, next_t, origin, j + count, taken.localised, taken.arrivals, taken.wait, taken.takes)
