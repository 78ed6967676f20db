"""The macro-step barrier: releases out to the nodes, their answers in.

:meth:`Barrier.exchange` is one release and its gathering: a STEP (or a batched STEPS) frame
to the nodes due, or, in process where the plan allows, one call per node; then every answer
due at the step's end, sorted by the releases' ledger (ledger.py) as it comes, with what else
the inbox holds taken in on the way (liveliness, HELLOs, samples, checkpoint states). The
master algorithms take their steps through it (algorithms/interface.py's Barrier).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

from hycosim.core import frames
from hycosim.core.config import LoadedProject
from hycosim.master.async_sources import SampleHistory
from hycosim.master.checkpointing import Checkpointing
from hycosim.master.coordinator import Coordinator
from hycosim.master.intake import Dropped, Intake
from hycosim.master.ledger import ENDED, LATER, TAKE, Ledger
from hycosim.master.membership import Membership
from hycosim.master.recorder import Recorder
from hycosim.master.routing import OutputView, Router
from hycosim.master.run_state import MESSAGE_MAX, Ending, ModelEnded, Progress, RunError
from hycosim.transport.inbox import LOCAL
from hycosim.transport.keys import ProjectKeys
from hycosim.transport.local_bus import DirectStep
from hycosim.transport.session import FrameTooLarge


def too_large(k: int, t: float, inputs: Mapping[str, list[Any]], exc: FrameTooLarge) -> RunError:
    """The run's end when the release of step k cannot be carried, naming the largest inputs."""
    return RunError(f"the release of step {k} (t={t:g} s) is {exc}; largest inputs, by node: "
                    f"{frames.largest_values(inputs.items())}")


class Sent:
    """The releases a node that comes back needs again: the run's START (an asynchronous source's
    clock), the last release, and the last that named each node."""

    def __init__(self) -> None:
        self.start: bytes | None = None
        self.last: bytes | None = None
        self.of: dict[str, bytes] = {}


class Barrier:
    """Releases and gathering for one run. ``outputs``: every node's latest outputs (a source's
    as held at the current point); ``point``: the point the loop is at (the last recorded,
    should a node end the run now)."""

    def __init__(self, loaded: LoadedProject, router: Router, coordinator: Coordinator, recorder: Recorder,
                 members: Membership, checkpointing: Checkpointing, progress: Progress, log: Any):
        project = loaded.project
        self.project, self.cosim, self.coupling = project, project.coSimulation, loaded.coupling
        self.router, self.coordinator, self.recorder = router, coordinator, recorder
        self.members, self.checkpointing, self.progress, self.log = members, checkpointing, progress, log
        self.intake = Intake(project.nodeLists)
        # Each stepping node's ``up`` key: its answers are taken on the flat path (gather) when
        # they are exactly what it owes; anything else goes through take_in.
        keys = ProjectKeys(project.projectName)
        self._up_nodes = {keys.up(n.nodeName): n.nodeName for n in project.stepping_nodes()}
        self.stepping = [n.nodeName for n in project.stepping_nodes()]
        # Asynchronous nodes played from a recording take part in the barrier: each point waits
        # for the samples the recorded run had by then, so that a replay gives the same values.
        self.paced = [n.nodeName for n in project.paced_nodes()]
        # Each stepping node's outstanding step and the answers kept for later points; batched
        # releases (STEPS, multi-rate) span ``span`` base steps once the nodes said they can.
        self.ledger = Ledger(self.stepping, self.paced, self.coupling.rates)
        self.span = 1
        self.last_point = float("inf")  # the index of the point at stopTime, on a grid from startTime
        self.histories = {n.nodeName: SampleHistory([p.start_value() for p in n.output])
                          for n in project.async_nodes()}
        self.outputs: dict[str, list[Any]] = {
            n.nodeName: [p.start_value() for p in n.output] for n in project.nodeLists}
        self.input_labels = {n.nodeName: [f"{n.nodeName}.{p.name}" for p in n.input] for n in project.nodeLists}
        self.ending = Ending()  # a node's model that ended the run
        self.messages = {"releases": 0, "received": 0}  # release frames sent, node frames taken in
        self.sent = Sent()
        self.point = 0
        self.direct: Mapping[str, DirectStep] | None = None  # in process, where the plan allows: steps as calls
        self.inbox: Any = None
        self.release: Any = None

    def connect(self, inbox: Any, release: Any) -> None:
        """The transport's inbox (node frames in) and release channel (frames out), once open."""
        self.inbox, self.release = inbox, release

    # --- the algorithms' view (algorithms.interface.Barrier) ------------------------------

    @property
    def meta(self) -> dict[str, Any]:
        """The run's meta.json, written at the end however the run ends (the recorder's)."""
        return self.recorder.meta

    @property
    def order(self) -> list[str]:
        """Gauss-Seidel's order of the stepping nodes."""
        return list(self.coupling.order)

    @property
    def inputs(self) -> dict[str, list[Any]]:
        """The inputs the next exchange steps on: the router's, routed at the point."""
        return self.router.inputs

    @inputs.setter
    def inputs(self, value: dict[str, list[Any]]) -> None:
        self.router.inputs = value

    def route_into(self, node: str, mode: str) -> None:
        """Route ``node``'s inputs again in ``mode`` from the outputs held now."""
        self.router.route_into(node, mode, self.outputs)

    def candidate(self, mode: str) -> dict[str, list[Any]]:
        """The inputs the outputs held now would route to in ``mode``, the router's left as they are."""
        return self.router.candidate(mode, self.outputs)

    def guard_pending(self) -> bool:
        """Whether the guard of an event not in force holds on the outputs held now."""
        return self.coordinator.pending_guard_holds(OutputView(self.router.output_index, self.outputs))

    def rollback(self, k: int, t: float) -> None:
        """Tell every node to go back to point ``k`` (at ``t``), whose state it saved before the step (a
        ROLLBACK)."""
        self.release.put(frames.encode(frames.ROLLBACK, k, t))

    def exchange(self, nodes: list[str] | None, k: int, t: float, h: float, mode: str, *,
                 times: list[float] | None = None, inputs: dict[str, list[Any]] | None = None,
                 slopes: dict[str, Any] | None = None, meanwhile: Callable[[], None] | None = None,
                 since: float | None = None) -> dict[str, float]:
        """Release step k (t → t + h) to ``nodes`` (None: every node due at k), run ``meanwhile``
        while they integrate (work there, recording the point, is off the barrier's critical
        path; it runs also when the release failed, so that the point stays recorded), and
        gather the outputs due at the step's end (``times``: a batched release over these base
        points, gathered at the last). Return each answer's seconds after ``since``."""
        released_at = time.perf_counter()
        since = released_at if since is None else since
        if self.direct is not None:
            try:
                return self.call(self.stepping if nodes is None else nodes, k, t, h, mode, since, inputs)
            finally:
                if meanwhile is not None:
                    meanwhile()
        due = nodes if nodes is not None else (self.coupling.due(k) if self.coupling.multirate else self.stepping)
        try:
            self.send(k, t, h, mode, due, released_at, times, inputs, slopes)
        finally:
            if meanwhile is not None:
                meanwhile()
        return self.gather(k + 1 if times is None else k + len(times) - 1, since,
                           None if nodes is None else set(nodes))

    # --- releases out ----------------------------------------------------------------------

    def send(self, k: int, t: float, h: float, mode: str, nodes: list[str], released_at: float,
             times: list[float] | None = None, inputs: dict[str, list[Any]] | None = None,
             slopes: dict[str, Any] | None = None) -> None:
        """Send the release of step k to ``nodes``: each owes its outputs, labelled k + 1, at the
        end of its own step (k + its rate, or the last point). ``times``: a batched release
        over these base points, after which a node as fast as the batch or faster owes its
        outputs (one BATCH, with those of its steps before the last)."""
        inputs = {n: (inputs or self.router.inputs)[n] for n in nodes}
        if times is None:
            frame = frames.encode(frames.STEP, k, t, h, mode, inputs, self.coordinator.driven_nodes(), slopes or {})
        else:
            frame = frames.encode(frames.STEPS, k, times, mode, inputs, self.coordinator.driven_nodes())
        self.sent.last = frame
        try:
            self.release.put(frame)
        except FrameTooLarge as exc:
            raise too_large(k, t, inputs, exc) from None
        self.messages["releases"] += 1
        self.ledger.released(nodes, k, released_at, count=1 if times is None else len(times) - 1,
                             batched=times is not None, span=self.span, last_point=self.last_point)
        for n in nodes:
            self.sent.of[n] = frame

    def call(self, nodes: list[str], k: int, t: float, h: float, mode: str, released_at: float,
             inputs: dict[str, list[Any]] | None = None) -> dict[str, float]:
        """The release of step k to ``nodes`` hosted in process, as calls: each steps on its
        inputs and returns its outputs at t + h, checked by the intake as an OUTPUTS frame's
        are (Intake.check_direct); return arrival offsets. A node whose model ended the run or
        failed sent its END instead, which is gathered as in a release by frames."""
        direct, outputs, check = self.direct, self.outputs, self.intake.check_direct
        inputs = inputs or self.router.inputs
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
            except ModelEnded:
                self.ending.arrivals.update(arrivals)
                raise
        return arrivals

    def replay(self, node: str) -> None:
        """A node lost within its grace came back: an asynchronous source needs the run's START
        (its clock); the others, a played one included, the last release."""
        last = (self.sent.start if self.project.node(node).asynchronous and node not in self.paced
                else self.sent.of.get(node, self.sent.last))
        if last is not None:
            try:
                self.release.put(frames.encode(frames.REPLAY, node, last))
            except FrameTooLarge as exc:
                raise RunError(f"cannot replay the last release to {node!r}: {exc}") from None

    def broadcast_stop(self, reason: str, step: int) -> None:
        """Tell every node the run ends at ``step`` and why (a STOP); a session already gone is let
        go."""
        try:
            self.release.put(frames.encode(frames.STOP, step, reason))
        except Exception:  # the session may be gone with Ctrl-C
            pass

    # --- answers in ---------------------------------------------------------------------

    def take_in(self, key: str, payload: bytes, step: int, collecting: bool) -> tuple[str, frames.Frame] | None:
        """Take in one message of the inbox (``key``: the node's ``up`` key, or LOCAL for a
        liveliness change) while point ``step`` is gathered (-1: while the nodes attach).
        Liveliness, samples, states and HELLOs are handled here; a node's OUTPUTS, BATCH or END
        is returned as (node, frame); anything the intake refuses is dropped and counted."""
        members = self.members
        if key == LOCAL:
            live = frames.decode(payload)
            if live.node in members.names:  # not the server's own token, nor one no node of this project holds
                if members.on_live(live.node, live.alive, step, collecting):
                    self.replay(live.node)
                self.progress.attached = sorted(members.alive)
            return None
        node = ProjectKeys.last_chunk(key)
        try:
            frame = self.intake.accept(node, payload)
        except Dropped as exc:
            self.intake.drop(exc.reason, exc.detail, step, node if node in members.names else "")
            return None
        if frame.kind == frames.SAMPLE:
            self.histories[node].add(float(frame.t), frame.values)
            # Received while point ``step`` is gathered: usable from that point on.
            self.recorder.sample(node, max(step, 0), float(frame.t), frame.values)
            return None
        if frame.kind == frames.STATE:
            self.checkpointing.on_state(node, frame, step, self.intake.drop)
            return None
        if frame.kind == frames.HELLO:
            members.on_hello(node, frame.capabilities, step, self.intake.drop, self.checkpointing.note_recovery)
            return None
        self.messages["received"] += 1
        return node, frame

    def wait_for_nodes(self) -> None:
        """Until every node holds its liveliness token (attachTimeout names the missing ones)."""
        expected = {n.nodeName for n in self.project.nodeLists}
        deadline = time.monotonic() + self.cosim.attachTimeout
        while not expected <= self.members.alive:
            msg = self.inbox.recv(deadline - time.monotonic())
            if msg is None:
                missing = sorted(expected - self.members.alive)
                raise RunError(f"timed out after {self.cosim.attachTimeout:g} s waiting for node(s) "
                               f"{', '.join(missing)} to attach to {self.project.serverIP}")
            self.take_in(*msg, step=-1, collecting=False)
        self.log.info("all nodes attached", nodes=sorted(self.members.alive))

    def await_departures(self, timeout: float = 3.0) -> None:
        """After STOP, give the nodes a moment to leave before this session closes: closing at
        once can drop the STOP still queued for a node, which then sees only the server vanish."""
        deadline = time.monotonic() + timeout
        try:
            while self.members.alive and time.monotonic() < deadline:
                msg = self.inbox.recv(deadline - time.monotonic())
                if msg is None:
                    break
                key, payload = msg
                if key == LOCAL:
                    live = frames.decode(payload)
                    if not live.alive:
                        self.members.alive.discard(live.node)
        except Exception:  # shutting down: never mask the run's own outcome
            pass

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
            pending = {*self.stepping, *self.paced}
        arrivals: dict[str, float] = {}
        for node, frame in self.ledger.kept_for(pending):
            self._take(node, frame, released_at, pending, arrivals)
        deadline = time.monotonic() + self.cosim.stepTimeout
        # Read once: this loop runs for every answer of every step, and each instruction of it
        # counts (benchmarks/FINDINGS.md, 2026-12-04, seventh entry).
        up_nodes, owes, outputs_in = self._up_nodes, self.ledger.owes_outputs, self.intake.plain_outputs
        members, recv, outputs = self.members, self.inbox.recv, self.outputs
        monotonic, perf_counter = time.monotonic, time.perf_counter
        flat = 0  # answers taken on the flat path, counted once at the end
        try:
            while pending:
                if members.lost:
                    deadline, wait = self._patience(deadline, step)
                else:
                    wait = deadline - monotonic()  # a wait already past returns what is queued, or None
                msg = recv(wait)
                if msg is None:
                    if members.lost:
                        continue  # _patience reports a node lost too long
                    raise RunError(f"timed out after {self.cosim.stepTimeout:g} s at step {step} (t="
                                   f"{self.members.time_of(step):g} s) waiting for outputs of {', '.join(sorted(pending))}")
                key, payload = msg
                # No None among the nodes pending: a key that is no node's is not pending either.
                if (node := up_nodes.get(key)) in pending and (owed := owes.get(node)) is not None:
                    values = outputs_in(node, payload, owed[0])
                    if values is not None:  # a stepping node's outputs, all as owed: what _take does, flat
                        flat += 1
                        pending.discard(node)
                        outputs[node] = values
                        arrivals[node] = perf_counter() - owed[1]
                        continue
                self._sort_in(key, payload, step, released_at, pending, arrivals)
        finally:
            self.messages["received"] += flat
        if self.ending.inside:
            raise ModelEnded
        return arrivals

    def _sort_in(self, key: str, payload: bytes, step: int, released_at: float, pending: set[str],
                 arrivals: dict[str, float]) -> None:
        """One message of the inbox while point ``step`` is gathered, other than a stepping
        node's outputs as owed (those the gathering takes flat): taken in, and where it is a
        node's answer, sorted by the ledger."""
        got = self.take_in(key, payload, step, True)
        if got is None:
            return
        node, frame = got
        if frame.kind == frames.END and (self.project.node(node).asynchronous or (
                frame.step == self.ledger.label(node, step) + 1 and not frame.clean)):
            # A source stopped or failed (never clean: the intake), or a node stopped
            # (SIGTERM) while waiting for a release: it names the next step.
            self.on_end(node, frame)
        verdict = self.ledger.sort(node, frame, step, pending)
        if verdict is TAKE:
            self._take(node, frame, released_at, pending, arrivals)
        elif verdict is LATER:
            self.ledger.keep(node, frame)
        elif verdict is ENDED:
            self.on_end(node, frame)
            # The others' outputs at the step's end (inside a batch: their batches, which
            # hold the points its earlier steps reached) are gathered before the run ends.
            pending.discard(node)
            self.ledger.earlier[node] = frame.earlier
            arrivals[node] = self.ledger.since_release(node, released_at)
            self.ending.inside.add(node)
            self.ending.arrivals = arrivals
        else:
            self.intake.drop(verdict.reason, verdict.detail, step, node)

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
        node, since = min(self.members.lost.items(), key=lambda item: item[1])
        grace = self.members.grace()
        if time.monotonic() - since > grace:
            raise RunError(f"node {node!r} was lost at step {step} (t={self.members.time_of(step):g} s) and did not "
                           f"come back within the link grace of {grace:g} s")
        deadline = max(deadline, time.monotonic() + self.cosim.stepTimeout)
        return deadline, max(min(deadline, since + grace + 0.01) - time.monotonic(), 0.0)

    def on_end(self, node: str, frame: frames.Frame) -> None:
        """A node's END instead of its outputs: its model ended the run (the caller gathers the
        others' outputs of the release before it ends), or failed."""
        t, clean, message, last = frame.t, frame.clean, frame.message, frame.last
        # The point the run's records end at (inside a batched release: its first, until the
        # points its steps before reached are recorded).
        message, k = message[:MESSAGE_MAX], self.point
        if not clean:
            # The node's runtime names itself and the step; a message that does not is prefixed.
            # A source lives on the wall clock and knows no step: the run's is added.
            at = (f" (the run at step {k}, t={self.members.time_of(k):g} s)"
                  if self.project.node(node).asynchronous else "")
            raise RunError(message + at if message.startswith(f"node {node!r}")
                           else f"node {node!r} failed at step {k} (t={self.members.time_of(k):g} s): {message}")
        if self.ending.inside:
            return  # another node ended in this release first: the run ends by its word
        self.ending.by = {"node": node, "step": k, "t": t, "message": message}
        self.ending.values = last
        self.log.info("node ended the simulation", node=node, step=k, t=t, message=message)
