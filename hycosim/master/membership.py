"""Who takes part in a run: the nodes' liveliness tokens, their HELLOs (what each can do), the
nodes lost within their grace, and the restarts that send the run back to a checkpoint."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from hycosim.core import frames
from hycosim.core.schema import Project
from hycosim.master.intake import port_mismatch
from hycosim.master.run_state import Recover, RunError

Drop = Callable[[str, str, int, str], None]


class Membership:
    """The nodes attached, lost and restarted. ``checkpoints``: whether the run can go back to
    a checkpoint (a restarted node is then taken back, not fatal); ``starting``: the START's
    answers are gathered (no node has stepped: a lost one may be started again); ``restoring``:
    a checkpoint is being restored (the stepping nodes' new HELLOs are expected)."""

    def __init__(self, project: Project, meta: dict[str, Any], log: Any):
        self.project, self.cosim, self.meta, self.log = project, project.coSimulation, meta, log
        self.names = {n.nodeName for n in project.nodeLists}
        self.alive: set[str] = set()
        self.capabilities: dict[str, dict[str, Any]] = {}
        # Nodes whose token (re)appeared and whose HELLO has not come since: a HELLO is taken only
        # from a node new to the run or one whose process may have changed, so that a forged
        # one (the UIDs are in the project file) cannot pass for a restart and stop the run.
        self.fresh: set[str] = set()
        self.lost: dict[str, float] = {}  # node → when its token went, while within linkGrace
        self.reattached: dict[str, int] = {}
        self.went: dict[str, float] = {}  # node → when its token last went (recovery times are measured from it)
        self.checkpoints = False
        self.starting = False
        self.restoring = False

    def time_of(self, step: int) -> float:
        """The time of point ``step`` on the run's grid (a step before the start: the start)."""
        return self.cosim.startTime + max(step, 0) * self.cosim.stepSize

    def said(self, stepping: list[str]) -> dict[str, dict[str, Any]]:
        """What each stepping node said it can do (nothing, if it said no HELLO)."""
        return {n: self.capabilities.get(n, {}) for n in stepping}

    def tunable(self) -> dict[str, dict[str, Any]]:
        """Each node's tunable parameters and their start values, as its HELLO said (off the
        network: only names that are strings and values a parameter may have)."""
        found = {}
        for node, said in self.capabilities.items():
            values = said.get("tunable")
            found[node] = ({k: v for k, v in values.items() if type(k) is str and frames.tunable_value(v)}
                           if type(values) is dict else {})
        return found

    def grace(self) -> float:
        """How long a lost node is waited for: its linkGrace, or with checkpoints (and while the
        START is answered, when no node has stepped) its restart (attachTimeout: a new process
        attaches as a first one does)."""
        return max(self.cosim.linkGrace, self.cosim.attachTimeout if self.checkpoints or self.starting else 0.0)

    def on_live(self, node: str, alive: bool, step: int, collecting: bool) -> bool:
        """A node's liveliness token came or went (``step`` -1: while the nodes attach). True
        when a node lost within its grace came back: it needs its last release again."""
        if alive:
            self.alive.add(node)
            if node not in self.capabilities or node in self.lost:
                self.fresh.add(node)
            self.log.info("node attached", node=node, step=step)
            if node in self.lost:
                del self.lost[node]
                self.reattached[node] = self.reattached.get(node, 0) + 1
                return True
            return False
        if node not in self.alive:
            return False
        self.alive.discard(node)
        self.went[node] = time.monotonic()
        if step < 0:
            # Gone before the run started: nothing of it is lost, and a new process of it
            # attaches as the first did (its HELLO is taken as a first one).
            self.capabilities.pop(node, None)
            self.fresh.discard(node)
            return False
        if self.grace() > 0:
            self.lost[node] = time.monotonic()
            self.log.warning("node lost, waiting for it", node=node, step=step, grace_s=self.grace())
            return False
        why = self.meta.get("checkpoints", "")
        raise RunError(f"node {node!r} was lost at step {step} (t={self.time_of(step):g} s): "
                       "its liveliness token disappeared (process killed or link lost)"
                       + (f"; the run cannot go on from a checkpoint (checkpoints {why})"
                          if self.cosim.checkpointEvery is not None else ""))

    def on_hello(self, node: str, said: dict[str, Any], step: int, drop: Drop,
                 note_recovery: Callable[[dict[str, Any]], None]) -> None:
        """A node's HELLO: what it can do, from a node new to the run or a new process of one."""
        if node in self.capabilities and node not in self.fresh and node not in self.lost:
            drop("duplicate hello", f"{node} said HELLO again while its process held its token", step, node)
            return
        self.fresh.discard(node)
        if node in self.capabilities and step > 0 and said.get("restart") is True:
            self._restarted(node, step, note_recovery)
            if self.project.node(node).asynchronous:
                return  # a source lives on the wall clock: it just goes on sampling
        elif node in self.capabilities and step > 0 and not self.restoring:
            # A node process says HELLO once: this is a new process, whose model starts
            # from scratch while the others are at step k. Not a link cut to wait out.
            # (While the START is collected, a fresh start is all that was asked of it.)
            raise RunError(f"node {node!r} was started again at step {step} (t={self.time_of(step):g} s) while "
                           "the run was under way: the state it had is gone, so the run cannot go on; "
                           "start the run again")
        self.capabilities[node] = dict(said)
        differ = port_mismatch(self.project.node(node), self.capabilities[node].get("ports"))
        if differ is not None:
            # Its frames would all be dropped and the run would only time out.
            raise RunError(f"node {node!r} attached with another version of its entry in the project file: "
                           f"{differ}. Give every process the same project file")

    def _restarted(self, node: str, step: int, note_recovery: Callable[[dict[str, Any]], None]) -> None:
        """A node's new process said HELLO mid-run: go back to the last checkpoint, or say why not."""
        at = f"at step {step} (t={self.time_of(step):g} s)"
        if self.project.node(node).asynchronous and self.checkpoints:
            note_recovery({"node": node, "step": step, "t": self.time_of(step), "cause": "restarted",
                           "restored": None, "at": time.time()})
            self.log.warning("asynchronous node restarted", node=node, step=step)
            return
        if not self.checkpoints:
            why = self.meta.get("checkpoints", "off")
            raise RunError(f"node {node!r} was started again {at} while the run was under way: the state it had "
                           f"is gone and the run cannot go back to a checkpoint (checkpoints {why}); start the run again")
        raise Recover(node, step, "restarted")
