"""A running co-simulation as a passive observer sees it.

The feed asks the server's status queryable five times a second (who is attached, where the
run is, the points' outputs and inputs since its last question, the barrier over the last
second, the mode switches with their guard values) and watches the liveliness tokens. It publishes nothing, and it does
not subscribe to the releases and outputs themselves: on a small machine, taking every frame
of a fast run cost the run a third of its steps (benchmarks/dashboard_cost.py), where five answers
a second cost it 1–3 %. The server keeps its latest 4,096 points for the answers, and sends at
most 64 of those after the step asked for (evenly thinned): a slow run is plotted point by
point, a fast one thinned; ``hycosim dashboard RUN_DIR`` shows every step once recorded.

The status answer is checked before use (:func:`_checked_status`); anything else is left out.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any

import structlog
import zenoh

from hycosim.core import json_text
from hycosim.transport.keys import SERVER_TOKEN, ProjectKeys
from hycosim.transport.session import ConnectError, client_config, open_session
from hycosim.dashboard.changes import Watchers
from hycosim.dashboard.series import ThinnedSeries

POLL_S = 0.2  # how often the server is asked (the page is pushed each answer)
_NUMBER = (int, float)


@dataclass
class NodeView:
    """A node as the status answer describes it: name, UID, whether it is asynchronous, its ports,
    the host it runs on and how often it was restarted."""

    name: str
    uid: int
    asynchronous: bool
    inputs: list[str]
    outputs: list[str]
    host: str | None = None
    restarts: int = 0
    attached: bool = False
    lost: bool = False


def _number(value: Any) -> float | None:
    """A finite number as a float, or None (a bool, text, an int beyond floats: None)."""
    if type(value) not in _NUMBER:
        return None
    try:
        value = float(value)
    except OverflowError:
        return None
    return value if math.isfinite(value) else None


def _list(value: Any) -> list:
    return value if type(value) is list else []


def _names(value: Any) -> list[str]:
    return [a for a in _list(value) if type(a) is str]


def _read_status(payload: bytes) -> dict[str, Any] | None:
    """A status answer as it came (bytes), checked as by :func:`_checked_status`; None for
    anything that is not one (anyone may answer on the key)."""
    try:
        return _checked_status(json_text.loads(payload))
    except ValueError:
        return None


def _checked_status(answer: Any) -> dict[str, Any] | None:
    """The parts of a status answer the page uses, or None if it is not one."""
    if type(answer) is not dict or type(answer.get("project")) is not str:
        return None
    nodes = []
    for n in _list(answer.get("nodes")):
        if not (type(n) is dict and type(n.get("name")) is str and type(n.get("uid")) is int
                and all(type(n.get(k)) is list and all(type(p) is str for p in n[k]) for k in ("input", "output"))):
            return None
        nodes.append(n)
    window = answer.get("window") if type(answer.get("window")) is dict else {}

    def per_node(key: str) -> dict[str, float]:
        got = window.get(key)
        return {str(k): v for k, v in got.items() if _number(v) is not None} if type(got) is dict else {}

    def values(got: Any) -> dict[str, list]:
        return {k: v for k, v in got.items() if type(k) is str and type(v) is list} if type(got) is dict else {}

    points = [[p[0], _number(p[1]), values(p[2]), values(p[3])] for p in _list(answer.get("points"))
              if type(p) is list and len(p) == 4 and type(p[0]) is int and _number(p[1]) is not None]

    return {"project": answer["project"], "nodes": nodes,
            "switches": [s for s in _list(answer.get("switches")) if type(s) is dict
                         and _number(s.get("t")) is not None][-200:],
            "dropped": {str(k): v for k, v in answer["dropped"].items() if type(v) is int}
            if type(answer.get("dropped")) is dict else {},
            "attached": _names(answer.get("attached")), "lost": _names(answer.get("lost")),
            "run": answer.get("run") if type(answer.get("run")) is str else "",
            "step": answer.get("step") if type(answer.get("step")) is int else 0,
            "t": _number(answer.get("t")), "mode": answer["mode"][:64] if type(answer.get("mode")) is str else "",
            "stopTime": _number(answer.get("stopTime")), "lateness_s": _number(answer.get("lateness_s")),
            "point_wall": _number(answer.get("point_wall")),
            "steps": window.get("steps") if type(window.get("steps")) is int else 0,
            "held": per_node("held"), "arrival_ms": per_node("arrival_ms"),
            "outputs": values(answer.get("outputs")), "inputs": values(answer.get("inputs")), "points": points,
            "ages": {k: _number(v) for k, v in answer["ages"].items() if type(k) is str}
            if type(answer.get("ages")) is dict else {}}


class LiveFeed:
    """What the page shows of a server at ``endpoint`` (its project: ``project``, or the one
    server that answers there)."""

    def __init__(self, endpoint: str, project: str | None = None, *, user: str | None = None,
                 password: str | None = None, tls: dict | None = None, retry_s: float = 2.0):
        self.endpoint = endpoint
        self.project = project
        self._auth = {"user": user, "password": password, "tls": tls}
        self._retry_s = retry_s
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._log = structlog.get_logger("dashboard")
        self.message = f"connecting to {endpoint}"
        self.state = "connecting"  # connecting, waiting (for the first step), running, ended
        self.nodes: dict[str, NodeView] = {}
        self.series: dict[str, ThinnedSeries] = {}
        self.status: dict[str, Any] = {}  # the latest checked answer
        self._since = -1  # the last step whose point is plotted (the server sends the ones after it)
        self.version = 0  # counts the answers taken (and the state changes): the page is pushed each
        self.watchers = Watchers()  # the pages' feeds, woken at each
        self._thread: threading.Thread | None = None
        self._busy = False  # the server's last reply said it was over its budget of answers

    # --- lifecycle ------------------------------------------------------------------

    def start(self) -> None:
        """Start asking the server in a thread of the feed's own."""
        self._thread = threading.Thread(target=self._run, name="dashboard-feed", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop asking and wait (up to 5 s) for the feed's thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)

    def _say(self, state: str, message: str) -> None:
        with self._lock:
            self.state, self.message = state, message
            self.version += 1
        self.watchers.notify()

    def _run(self) -> None:
        """Connect, watch, and connect again whenever the server cannot be reached."""
        while not self._stop.is_set():
            try:
                session = open_session(client_config(self.endpoint, timeout_s=2.0, **self._auth), self.endpoint)
            except ConnectError as exc:
                self._say("connecting", f"cannot reach the server: {exc}; retrying every {self._retry_s:g} s")
                self._stop.wait(self._retry_s)
                continue
            try:
                self._watch(session)
            except Exception as exc:  # noqa: BLE001 - the feed outlives whatever a session does; the page says so
                self._log.warning("feed lost the server", error=repr(exc))
                self._say("connecting", f"lost the server at {self.endpoint} ({exc}); retrying")
            finally:
                session.close()
            self._stop.wait(self._retry_s)

    def _watch(self, session: zenoh.Session) -> None:
        status = self._ask(session, self.project or "*")
        if status is None:
            self._say("connecting", (f"the server at {self.endpoint} is busy answering others; retrying" if self._busy
                                     else f"no hycosim server answers at {self.endpoint}"
                                     + (f" for project {self.project!r}" if self.project else "") + "; retrying"))
            return
        self.project = status["project"]
        self.take(status)
        watcher = session.liveliness().declare_subscriber(ProjectKeys(self.project).alive_all, self._on_alive,
                                                          history=True)
        try:
            missed = 0
            while not self._stop.wait(POLL_S):
                status = self._ask(session, self.project, self._since)
                if status is not None:
                    missed = 0
                    self.take(status)
                    continue
                missed += 1
                if missed >= 10 and self.state != "ended":
                    self._say("connecting", f"the server at {self.endpoint} "
                              + ("is busy answering others; retrying" if self._busy else "does not answer; retrying"))
                    return
        finally:
            watcher.undeclare()

    def _ask(self, session: zenoh.Session, project: str, since: int | None = None) -> dict[str, Any] | None:
        """The server's checked status answer (with its points after step ``since``), or None."""
        key = ProjectKeys(project).status
        self._busy = False
        try:
            for reply in session.get(key if since is None else f"{key}?since={since}", timeout=1.0):
                if reply.ok is None:  # a server over its budget of answers says so (server.answer_budget)
                    self._busy |= reply.err is not None and reply.err.payload.to_bytes().startswith(b"busy: ")
                    continue
                checked = _read_status(reply.ok.payload.to_bytes())
                if checked is not None:
                    return checked
        except zenoh.ZError:
            return None
        return None

    def take(self, status: dict[str, Any]) -> None:
        """A checked status answer: the nodes, the point's values into the series, the run's figures."""
        with self._lock:
            for n in status["nodes"]:
                view = self.nodes.get(n["name"])
                if view is None:
                    view = self.nodes[n["name"]] = NodeView(n["name"], n["uid"], n.get("async") is True,
                                                            n["input"], n["output"])
                    for port in (*view.outputs, *view.inputs):
                        self.series.setdefault(f"{view.name}.{port}", ThinnedSeries())
                view.host = n.get("host") if type(n.get("host")) is str else view.host
                view.restarts = n.get("restarts") if type(n.get("restarts")) is int else view.restarts
                view.attached = n["name"] in status["attached"]
                view.lost = n["name"] in status["lost"]
            if status["step"] < self._since:
                self._since = -1  # the run went back (to a checkpoint): its points come again
            # The points since the last answer (every one the server kept, thinned), else the latest.
            points = status["points"] or [[status["step"], status["t"], status["outputs"], status["inputs"]]]
            started = status["step"] > 0 or status["steps"] > 0
            for k, t, outputs, inputs in points:
                if not started or t is None:
                    continue
                for key, given in (("outputs", outputs), ("inputs", inputs)):
                    for name, values in given.items():
                        view = self.nodes.get(name)
                        if view is not None:
                            self._plot(name, getattr(view, key), t, values)
                self._since = max(self._since, k)
            if started and self.state != "ended":
                self.state, self.message = "running", "running"
            elif not started and self.state == "connecting":
                self.state, self.message = "waiting", "attached; waiting for the run's first step"
            self.status = status
            self.version += 1
        self.watchers.notify()

    def _plot(self, node: str, ports: list[str], t: float, values: list) -> None:
        for port, value in zip(ports, values):
            number = float(value) if type(value) is bool else _number(value)
            series = self.series.get(f"{node}.{port}")
            if series is not None and (number is not None or type(value) is float):  # NaN, ±inf: a gap
                series.add(t, number if number is not None else math.nan)

    def _on_alive(self, sample: zenoh.Sample) -> None:
        name = ProjectKeys.last_chunk(str(sample.key_expr))
        with self._lock:
            if name == SERVER_TOKEN and sample.kind == zenoh.SampleKind.DELETE and self.state == "running":
                self.state, self.message = "ended", "the server has left: the run is over"
            self.version += 1
            view = self.nodes.get(name)
            if view is not None:
                view.attached = sample.kind == zenoh.SampleKind.PUT
        self.watchers.notify()

    # --- what the page gets ----------------------------------------------------------

    def _scene(self) -> dict[str, list[list[float]]]:
        """Each node's points in the x–z plane, a rendering of the twin: its outputs named
        ``P_x`` and ``P_z`` (the rod's grasp point and tip, the robot's TCP), in port order."""
        scene: dict[str, list[list[float]]] = {}
        for name, values in self.status.get("outputs", {}).items():
            view = self.nodes.get(name)
            if view is None:
                continue
            by_port = dict(zip(view.outputs, values))
            points = []
            for port in view.outputs:
                if port.endswith("_x") and f"{port[:-2]}_z" in by_port:
                    x, z = _number(by_port[port]), _number(by_port[f"{port[:-2]}_z"])
                    if x is not None and z is not None:
                        points.append([x, z])
            if points:
                scene[name] = points
        return scene

    def _values(self) -> dict[str, Any]:
        """Every port's value at the latest point (``node.port`` → value), for the page's port list."""
        values: dict[str, Any] = {}
        for key in ("outputs", "inputs"):
            for name, given in self.status.get(key, {}).items():
                view = self.nodes.get(name)
                if view is not None:
                    values.update((f"{name}.{port}", value) for port, value in zip(getattr(view, key), given))
        return values

    def ports(self) -> list[str]:
        """The ports plotted so far, as ``node.port``."""
        with self._lock:
            return list(self.series)

    def snapshot(self, select: list[str], held: dict[str, tuple[int, int]] | None = None) -> dict[str, Any]:
        """The page's view; each selected series as what a page ``held`` lacks (dashboard.series)."""
        held = held or {}
        with self._lock:
            s = self.status
            shares, arrival = s.get("held", {}), s.get("arrival_ms", {})  # of the barrier, by node
            nodes = [{"name": v.name, "attached": v.attached, "lost": v.lost, "host": v.host, "restarts": v.restarts,
                      "asynchronous": v.asynchronous, "held_share": shares.get(v.name),
                      "mean_arrival_ms": arrival.get(v.name)} for v in self.nodes.values()]
            return {"source": "live", "state": self.state, "message": self.message, "project": self.project or "",
                    "run": s.get("run", ""), "endpoint": self.endpoint, "step": s.get("step", 0), "t": s.get("t"),
                    "mode": s.get("mode", ""), "stopTime": s.get("stopTime"), "steps_per_s": s.get("steps", 0),
                    "lateness_s": s.get("lateness_s"), "point_wall": s.get("point_wall"), "nodes": nodes,
                    "switches": list(s.get("switches", [])), "dropped": dict(s.get("dropped", {})),
                    "scene": self._scene(), "ages": dict(s.get("ages", {})), "values": self._values(),
                    "series": {p: d for p in select if p in self.series
                               and (d := self.series[p].since(*held.get(p, (-1, 0)))) is not None}}
