"""Checkpoints during a run: when one is due, the nodes' states gathered as they come and
written with the server's (checkpoints.py is the files), the one to go back to, and the
record of every restart and resume."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

from hycosim.core import frames
from hycosim.core.config import LoadedProject
from hycosim.master import checkpoints, plans
from hycosim.master.recorder import Recorder
from hycosim.master.run_state import PendingCheckpoint, Recover, RunError

Drop = Callable[[str, str, int, str], None]


class Checkpointing:
    """``on`` once every stepping node said it can serialise its state; ``at``: the next
    checkpoint's time; ``recoveries``: the restores done (node, steps, cause, time)."""

    def __init__(self, loaded: LoadedProject, recorder: Recorder, stepping: list[str], log: Any):
        self.loaded, self.project, self.recorder, self.stepping, self.log = (
            loaded, loaded.project, recorder, stepping, log)
        self.cosim = loaded.project.coSimulation
        self.on = False
        self.at = self.cosim.startTime
        self.pending: PendingCheckpoint | None = None
        self.taken = 0
        self.recoveries: list[dict[str, Any]] = []

    def plan(self, said: Any) -> bool:
        """Whether checkpoints are taken; say why not in the metadata."""
        plan = plans.checkpoints(self.cosim, said)
        self.recorder.meta["checkpoints"] = plan.words
        if plan.why:
            self.log.warning("no checkpoints", cannot_serialise=plan.why)
        self.on = plan.on
        return plan.on

    def due(self, k: int, t: float, final: bool, period: int) -> bool:
        """Whether one is taken at point k (t). A multi-rate run's wait for a point where no
        node is inside its step."""
        return (self.on and self.at - 1e-9 * self.cosim.stepSize <= t and not final and k % period == 0)

    def go_on_from(self, t: float) -> None:
        """The next checkpoint after one at (or back at) ``t``."""
        self.at = checkpoints.next_time(t, self.cosim.startTime, self.cosim.checkpointEvery)

    def ask(self, k: int, server: dict[str, Any]) -> bytes:
        """Keep the server's state at point k until the nodes' come; return the frame asking for them."""
        if self.pending is not None:
            missing = sorted(set(self.stepping) - set(self.pending.states))
            self.log.warning("checkpoint abandoned", step=self.pending.step, missing=missing)
        self.pending = PendingCheckpoint(k, server)
        self.go_on_from(server["t"])
        return frames.encode(frames.CHECKPOINT, k)

    def on_state(self, node: str, frame: frames.Frame, step: int, drop: Drop) -> None:
        """A piece of a node's state for the checkpoint being gathered; the checkpoint is written
        once every stepping node's state is whole."""
        at = frame.step
        p = self.pending
        if p is None or at != p.step or self.project.node(node).asynchronous:
            drop("stale state", f"{node} sent its state at step {at}, no checkpoint of it is gathered", step, node)
            return
        data = p.chunks.setdefault(node, frames.Chunks()).add(at, frame.index, frame.count, frame.chunk)
        if data is None:
            return
        p.states[node] = data
        if len(p.states) < len(self.stepping):
            return
        self.pending = None
        try:
            path = checkpoints.write(self.recorder.run_dir, p.step, p.server, p.states, self.loaded.digest)
        except checkpoints.CheckpointError as exc:
            self.log.warning("checkpoint not written", step=p.step, error=str(exc))
            self.recorder.meta["checkpoint_error"] = str(exc)
            return
        self.taken += 1
        self.recorder.meta["last_checkpoint"] = {"step": p.step, "t": p.server["t"], "path": str(path)}
        self.log.info("checkpoint", step=p.step, t=p.server["t"], bytes=sum(map(len, p.states.values())))

    def latest(self, cause: Recover) -> checkpoints.Checkpoint:
        """The last readable checkpoint to go back to (those passed over named in the metadata)."""
        cp, passed = checkpoints.latest(self.recorder.run_dir, self.loaded.digest, project=self.project)
        for reason in passed:
            self.log.warning("checkpoint passed over", reason=reason)
            self.recorder.meta.setdefault("checkpoints_passed_over", []).append(reason)
        if cp is None:
            raise RunError(f"node {cause.node!r} was started again at step {cause.step}, and no checkpoint "
                           f"of the run could be read to go on from" + (f": {'; '.join(passed)}" if passed else ""))
        self.log.warning("restoring checkpoint", node=cause.node, lost_at=cause.step, step=cp.step)
        self.pending = None
        return cp

    def restore_frames(self, cp: checkpoints.Checkpoint, paced: list[str], saves_states: bool) -> Iterator[bytes]:
        """The RESTORE frames that give every node its state at ``cp``."""
        # As START's: a node started again must save its state before each step as the others do,
        # or the retakes of iterative coupling and step control would step it on from where it was.
        options = {"checkpoint": saves_states}
        for node in paced:  # no state: a played source goes on from the checkpoint's point
            yield frames.encode(frames.RESTORE, node, cp.step, cp.server["t"], 0, 1, b"", options)
        for node in self.stepping:
            if node not in cp.states:
                raise RunError(f"checkpoint {cp.path} holds no state of node {node!r}")
            pieces = frames.state_chunks(cp.states[node])
            for i, chunk in enumerate(pieces):
                yield frames.encode(frames.RESTORE, node, cp.step, cp.server["t"], i, len(pieces), chunk, options)

    def note_recovery(self, entry: dict[str, Any]) -> None:
        """A restart or resume, in the metadata at once (the run may yet die)."""
        self.recoveries.append(entry)
        earlier = self.recorder.meta.get("recoveries")  # a resumed run's, from its meta.json
        self.recorder.meta["recoveries"] = (earlier if type(earlier) is list else []) + [entry]
        self.recorder.write_meta()
