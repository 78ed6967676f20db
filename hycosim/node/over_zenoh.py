"""A node over Zenoh: its process attached to the server's session, the frames pulled from its
link within the bounds each phase allows (the link grace, the attach and step timeouts) and
given to :meth:`NodeRuntime.handle`; while stepping, each plain release is stepped on a flat
path beside it (:meth:`ZenohNode._releases_plainly`). An asynchronous source runs here only."""

from __future__ import annotations

import time

from hycosim.core import frames, signals
from hycosim.node.interface import AsyncSource
from hycosim.node.receiving import NodeRunError
from hycosim.node.releases import REFUSED
from hycosim.node.replay import SamplePlayer
from hycosim.node.runtime import NodeRuntime, PHASE_RESTART, PHASE_RESTORING, PHASE_START, PHASE_STEPPING
from hycosim.node.sources import run_source, source_start
from hycosim.transport.node_side import ZenohNodeLink
from hycosim.transport.session import FrameTooLarge


class ZenohNode(NodeRuntime):
    """One node's process in a distributed run: :meth:`run` until the run's STOP."""

    def run(self) -> None:
        """Attach to the server over Zenoh and take part in the run until its STOP."""
        self._setup()
        try:
            link = ZenohNodeLink.open(self.loaded, self.name, self.endpoint, self.password)
            self._log.info("attached", over=link.over)
            self.receiver.link, self.receiver.pulls = link, True
            try:
                if isinstance(self.impl, AsyncSource) and not isinstance(self.impl, SamplePlayer):
                    start, self._returning = source_start(self.receiver, self.cosim)
                    if start.kind == frames.STOP:
                        self._on_stop(start)
                    else:
                        self.outbox.send(self.outbox.hello(self.impl, False, restart=self._returning))
                        self.samples = run_source(self.impl, self.spec, self.cosim, start, self.outbox,
                                                  self.receiver, self._on_stop, self._log)
                    return
                done = False
                while not done:
                    if self._phase == PHASE_STEPPING and self.receiver.flat \
                            and self.receiver.server_lost is None:
                        done = self._releases_plainly()
                    else:
                        done = self.handle(self._pull())
            except KeyboardInterrupt as exc:
                self.outbox.say_stopped(exc, isinstance(self.impl, AsyncSource))
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
        if self._phase == PHASE_START:
            # The server times out the attach; outwait it so that its STOP, naming who is
            # missing, reaches this node rather than a timeout of our own.
            try:
                return self.receiver.wait(self.cosim.attachTimeout + self.cosim.stepTimeout, "START")
            except NodeRunError as exc:
                raise NodeRunError(f"{exc}{self.link.other_projects()}") from None
        if self._phase == PHASE_RESTART:
            frame = self.receiver.next_frame(max(0.0, self._restart_deadline - time.monotonic()))
            if frame is None:
                wait = self.cosim.attachTimeout + self.cosim.stepTimeout
                raise NodeRunError(f"node {self.name!r}: the run on {self.endpoint} was already under way "
                                   f"(step {self._restoring_step}) when it attached, and the server did not restore "
                                   f"it within {wait:g} s: a node restarted mid-run goes on only from a checkpoint "
                                   "(coSimulation.checkpointEvery)")
            return frame
        if self._phase == PHASE_RESTORING:
            frame = self.receiver.next_frame(self.cosim.stepTimeout)
            if frame is None:
                return self._restore_cut_short()
            return frame
        # The server enforces step timeouts; a node only needs to notice the server is gone,
        # which liveliness tells; this bound is the last resort for a frozen server.
        return self.receiver.wait(self.cosim.stepTimeout + 30.0, "release")

    def _releases_plainly(self) -> bool:
        """Over Zenoh, while stepping: the releases as they come, each plain STEP
        (``ReleaseReader.plain``) stepped here, flat, as _on_release and _step_model step it; any
        other frame through :meth:`handle`. True once the node is done; False where the whole
        way must take over (a link cut to wait out, a phase other than stepping).

        Every step of a run comes here, where the layers of the general path cost a node as
        much CPU as the floor's whole step (benchmarks/FINDINGS.md, 2026-12-04)."""
        receiver, link, impl, at, outbox = self.receiver, self.link, self.impl, self._stepping, self.outbox
        plain_for, in_names, uid = receiver.releases.plain_decoder, self._in_names, self.spec.UID
        pack, encode, packed = outbox.pack, frames.encode, frames.packed
        receive, put, limit = link.receive, link.publisher.unchecked_put, link.publisher.limit
        held, VERSION, OUTPUTS = signals.HELD, frames.VERSION, frames.OUTPUTS
        # A model that steps on lists (an FMU, Node.listed_step) takes the inputs as read and
        # gives its outputs as the wire has them: no dict either way, no conversion. Asked at
        # every entry: a restored or restarted model may step through other objects.
        listed = impl.listed_step(list(in_names), list(self.spec.output))
        bound = self.cosim.stepTimeout + 30.0  # as _pull's: the last resort for a frozen server
        # Read flat only where the flat step will take it (not decoded twice otherwise): not in
        # a run with checkpoints or for a node of its own rate, nor while a state waits to go
        # (only a frame taken the whole way below asks for one). The decoder takes the releases
        # of the mode the node steps in alone: a release that switches it (the first one
        # included) goes the whole way, which tells the model, and the mode needs no check here.
        flat = not at.checkpoint and self._rate == 1
        decode = plain_for(at.mode, at.driven) if flat and at.pending_state is None else None
        while True:
            msg = receive(bound)
            if msg is None:
                raise receiver.silence(bound, "release")
            _, payload = msg  # (key, payload): a STEP is known by its payload alone
            release = None
            if decode is not None:  # LIVE news (a session-local payload) is no STEP: the decoder refuses it
                try:  # ReleaseReader.plain, without its call
                    release = decode(payload)
                except REFUSED:
                    pass
            if release is None:
                frame = receiver.take(msg)
                if frame is not None and self.handle(frame):
                    return True
                if self._phase != PHASE_STEPPING or receiver.server_lost is not None:
                    return False
                decode = plain_for(at.mode, at.driven) if flat and at.pending_state is None else None
                continue
            k, t, h = release.step, release.t, release.h
            try:
                if listed is not None:
                    values = listed(t, h, release.inputs.mine)
                else:
                    impl.step(t, h, dict(zip(in_names, release.inputs.mine)))
                    values = pack(impl.outputs())
                try:  # frames.encode's packing, without its call
                    out = packed((VERSION, OUTPUTS, uid, k + 1, t + h, values))
                except TypeError:
                    out = encode(OUTPUTS, uid, k + 1, t + h, values)
                # Outbox.send_outputs and FramePublisher.put, without their calls: measured, sent
                # and counted with no stop between.
                held.depth += 1
                try:
                    if len(out) > limit:
                        raise FrameTooLarge(len(out), limit)
                    put(out)
                    outbox.steps = k + 1
                finally:
                    held.depth -= 1
                    if held.pending is not None:
                        signals.raise_held()
            except FrameTooLarge as exc:
                self._step_failed(outbox.too_large(out, exc), k, t, impl=impl)
                return True
            except Exception as exc:
                self._step_failed(exc, k, t, impl=impl)
                return True  # the model ended the simulation (a failure raised)
            at.done, at.last_out = k, out

    def _restore_cut_short(self) -> frames.Frame:
        """No next piece of a state within the step timeout: as a piece that is not one."""
        self.drops.drop("not a release", f"the state to restore at step {self._restoring.step} came in part",
                        self.steps)
        self._restore_failed()
        return self._pull()
