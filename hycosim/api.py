"""A run driven from Python: :func:`open` a project, then step it, look at its ports, end it.

The run is the one ``hycosim run --in-process`` makes (``distributed=True``: ``hycosim run``'s,
each node a process of its own over Zenoh on loopback): the same master, nodes and run
directory, ``values.csv`` byte for byte. The master runs in a thread of its own and stops at
every macro-step point until this object lets it take the next step; while it stands there
its outputs are gathered and its inputs routed, so what :meth:`Simulation.get` reads is the
point's record. Leaving the ``with`` block (or :meth:`Simulation.close`) before the stop time
ends the run as stopped, every row recorded so far kept.
"""

from __future__ import annotations

import json
import math
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hycosim.core.config import ConfigError, LoadedProject, load_project, parse_project
from hycosim.core.hints import did_you_mean

# How often a waiting caller looks whether the run's thread is still there (a wait is never blind).
_LOOK_S = 0.5


class SimulationError(Exception):
    """What a run driven from Python raises: the project, a port, a time, a closed run, a run
    that failed. Each case is a subclass; the message names the project, port or time."""


class ProjectError(SimulationError):
    """The project cannot be run: its file has errors, or a node cannot be hosted in process."""


class PortError(SimulationError, KeyError):
    """A name that is no port of the project (``node.port``)."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


class TimeError(SimulationError):
    """A time the run cannot reach: past its stop time, or a step past its end."""


class ClosedError(SimulationError):
    """A call on a run that is closed."""


class OverrideError(SimulationError):
    """An override the port cannot take: no link feeds it, or the value is of another type or shape."""


class ParameterError(SimulationError):
    """A parameter no node declares tunable, or a value not of its type."""


class RunFailed(SimulationError):
    """The run failed (a node's model, a record that cannot be written); its run directory
    keeps what was recorded."""


@dataclass(frozen=True)
class Outcome:
    """How a run ended: ``status`` as ``meta.json`` says it (completed, stopped, failed, …), the
    exit code ``hycosim run`` would give, and its message."""

    status: str
    code: int
    message: str


class _Gate:
    """Where the master waits at each point until the caller lets it step on (thread-safe)."""

    def __init__(self) -> None:
        self._cv = threading.Condition()
        self.at: tuple[int, float] | None = None  # the point the master stands at
        self._until_step = 0  # it steps on from points before this one
        self._until_t = -math.inf  # and from points before this time
        self._open = False  # closing: every step at once, to the stop the caller asked for

    def hold(self, step: int, t: float) -> None:
        if self._open or (step < self._until_step and t < self._until_t):
            # Stepping on to where the caller asked (run_until): no lock taken, nobody woken.
            # go() is called only while the master stands here, so the two bounds read together.
            return
        with self._cv:
            self.at = (step, t)
            self._cv.notify_all()
            self._cv.wait_for(lambda: self._open or (step < self._until_step and t < self._until_t))
            self.at = None

    def go(self, step: int, t: float) -> None:
        """Let the master step on from every point before ``step`` and before time ``t``."""
        with self._cv:
            self._until_step, self._until_t = step, t
            self._cv.notify_all()

    def open_wide(self) -> None:
        with self._cv:
            self._open = True
            self._cv.notify_all()

    def wait(self, arrived, over, thread: threading.Thread) -> None:
        """Until ``arrived()`` (the caller's condition on :attr:`at`) or ``over()`` (the run ended);
        the run's thread is looked at every half second besides, so no wait outlives it."""
        with self._cv:
            while not self._cv.wait_for(lambda: arrived() or over() or not thread.is_alive(), timeout=_LOOK_S):
                pass


def _load(project: str | Path | dict[str, Any]) -> LoadedProject:
    try:
        if isinstance(project, dict):
            return parse_project(project, "<project dict>")
        path = Path(project)
        from hycosim.fmi.osp import OspError, imported_structure, is_structure

        if is_structure(path):
            try:
                path, _ = imported_structure(path)
            except OspError as exc:
                raise ProjectError(str(exc)) from None
        elif path.suffix.lower() == ".ssp":
            from hycosim.fmi.ssp import SspError, imported_project

            try:
                path = imported_project(path)
            except SspError as exc:
                raise ProjectError(str(exc)) from None
        return load_project(path)
    except ConfigError as exc:
        raise ProjectError(f"{exc.source}: " + "; ".join(i.render() for i in exc.issues)) from None


def _check_nodes(loaded: LoadedProject, base: Path) -> None:
    """ProjectError for a node whose model or FMU is not there (nothing started yet)."""
    from hycosim.node.loader import NodeLoadError, locate_node

    for spec in loaded.project.nodeLists:
        try:
            locate_node(spec, base)
        except NodeLoadError as exc:
            raise ProjectError(str(exc)) from None


def absolute_paths(doc: dict[str, Any], base: Path) -> dict[str, Any]:
    """The project with its nodes' FMU, recording and ``file.py`` model paths made absolute."""
    nodes = []
    for node in doc.get("nodeLists", []):
        node = dict(node)
        for key in ("fmu", "replay"):
            if isinstance(node.get(key), str):
                node[key] = str((base / node[key]).resolve())
        model = node.get("model")
        if isinstance(model, str) and ".py:" in model:
            file, _, cls = model.rpartition(":")
            node["model"] = f"{(base / file).resolve()}:{cls}"
        nodes.append(node)
    return {**doc, "nodeLists": nodes}


def open(project: str | Path | dict[str, Any], *, runs_dir: str | Path = "runs",  # noqa: A001
         distributed: bool = False) -> Simulation:
    """Start a run of ``project`` (a project file, an SSP package, an OSP system structure, or a
    project as a dict) and
    stop at its first point, t = startTime, with the initialisation done. Its run directory is
    made under ``runs_dir`` as ``hycosim run`` makes it. In this process by default; with
    ``distributed`` the master stays here and each node is a process of its own, attached over
    Zenoh on loopback (asynchronous sources too)."""
    if isinstance(project, dict) and distributed:
        # The node processes read the project from a file: the dict is written into the run's
        # folder, the files its nodes name made absolute (a dict's are relative to this folder).
        from hycosim.core.folders import run_dir_for

        _check_nodes(_load(project), Path.cwd())
        folder = run_dir_for(Path(runs_dir), _load(project).name)
        (folder / "project.json").write_text(json.dumps(absolute_paths(project, Path.cwd()), indent=1))
        return Simulation(_load(folder / "project.json"), Path(runs_dir), distributed=True, run_dir=folder)
    return Simulation(_load(project), Path(runs_dir), distributed=distributed)


class Simulation:
    """One run, driven step by step. Made by :func:`open`; use it in a ``with`` block."""

    def __init__(self, loaded: LoadedProject, runs_dir: Path, *, distributed: bool = False,
                 run_dir: Path | None = None):
        from hycosim.inprocess import CannotHost, check_hostable

        if not distributed:
            try:
                check_hostable(loaded)
            except CannotHost as exc:
                raise ProjectError(f"{exc.args[0].split(' (run it without')[0]} (open it with distributed=True)") from None
        else:  # what cannot load is named before a process starts
            _check_nodes(loaded, loaded.path.parent)
        self._distributed, self._run_dir = distributed, run_dir
        self._loaded = loaded
        self._cosim = loaded.project.coSimulation
        self._ports = {f"{n.nodeName}.{p.name}": (n.nodeName, "outputs", i)
                       for n in loaded.project.nodeLists for i, p in enumerate(n.output)}
        self._ports.update({f"{n.nodeName}.{p.name}": (n.nodeName, "inputs", i)
                            for n in loaded.project.nodeLists for i, p in enumerate(n.input)})
        self._gate = _Gate()
        self._relay = None
        self._result: tuple[int, Path | None, str] | None = None
        self._failure: BaseException | None = None
        self._closed = False
        self._over = False  # the run's thread is done with it
        self._thread = threading.Thread(target=self._run, args=(runs_dir,), name=f"hycosim-{loaded.name}",
                                        daemon=True)
        self._thread.start()
        self._gate.wait(lambda: self._gate.at is not None, lambda: self._over, self._thread)
        if self._gate.at is None and self._result is not None and self._result[1] is None:
            raise ProjectError(self._result[2])  # a model that could not load: nothing was run
        self._raise_if_failed()

    def _run(self, runs_dir: Path) -> None:
        import structlog

        from hycosim.inprocess import run_in_process

        def seen(relay: Any) -> None:
            self._relay = relay

        # A run sends structlog's lines to its own log file; the caller's setup is put back after.
        callers_logging = structlog.get_config()
        try:
            if self._distributed:
                self._result = self._run_distributed(runs_dir, seen)
            else:
                self._result = run_in_process(self._loaded, runs_dir=runs_dir, gate=self._gate, on_relay=seen)
        except BaseException as exc:  # told to the caller, in the caller's thread
            self._failure = exc
        finally:
            structlog.configure(**callers_logging)
            self._over = True
            self._gate.go(-1, -math.inf)  # wakes a waiting caller

    def _run_distributed(self, runs_dir: Path, seen) -> tuple[int, Path | None, str]:
        """The master here (its Zenoh router on a free loopback port), each node a process of
        its own, as ``hycosim run`` starts them; every process waited for, with a bound."""
        import subprocess
        import sys

        from hycosim.core.folders import run_dir_for
        from hycosim.embedded import free_loopback_endpoint
        from hycosim.master.main import serve

        endpoint = free_loopback_endpoint()
        run_dir = self._run_dir or run_dir_for(runs_dir, self._loaded.name)
        nodes = []
        try:
            for spec in self._loaded.project.nodeLists:
                with (run_dir / f"node-{spec.nodeName}.stderr.txt").open("w") as err:
                    nodes.append(subprocess.Popen(
                        [sys.executable, "-P", "-m", "hycosim", "node", spec.nodeName, str(self._loaded.path),
                         "--connect", endpoint, "--log-file", str(run_dir / f"node-{spec.nodeName}.log.jsonl")],
                        stdout=err, stderr=subprocess.STDOUT))
            return serve(self._loaded, listen=endpoint, run_dir=run_dir, gate=self._gate, on_relay=seen)
        finally:
            for proc in nodes:  # they leave on the server's STOP; a stuck one is stopped
                try:
                    proc.wait(timeout=15.0)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(timeout=10.0)

    # --- where the run is ------------------------------------------------------------

    @property
    def step_count(self) -> int:
        """The macro steps taken so far (the index of the point the run stands at)."""
        at = self._gate.at  # read once: the master clears it as it steps on
        if at is not None:
            return at[0]
        return self._relay.progress.step if self._relay is not None else 0

    @property
    def time(self) -> float:
        """The simulated time of the point the run stands at."""
        at = self._gate.at
        if at is not None:
            return at[1]
        return self._relay.progress.t if self._relay is not None else self._cosim.startTime

    @property
    def run_dir(self) -> Path | None:
        """The run directory, as ``hycosim run`` writes it."""
        if self._result is not None:
            return self._result[1]
        return self._relay.recorder.run_dir if self._relay is not None else None

    @property
    def outcome(self) -> Outcome | None:
        """How the run ended, once it has (None while it runs)."""
        if self._result is None:
            return None
        code, run_dir, message = self._result
        status = "failed"
        try:
            status = json.loads((run_dir / "meta.json").read_text()).get("status", status)
        except (OSError, ValueError, TypeError):
            pass
        return Outcome(str(status), code, message)

    @property
    def ended(self) -> bool:
        """Whether the run is over (its stop time reached, stopped, or failed)."""
        return self._over or not self._thread.is_alive()

    # --- driving it ------------------------------------------------------------------

    def step(self) -> float:
        """Take one macro step; return the new time."""
        self._check_open()
        if self.ended:
            raise TimeError(f"the run of {self._loaded.name!r} is over (t={self.time:g} s): no step is left")
        k = self.step_count
        self._advance(k + 1, math.inf, lambda at: at[0] > k)
        return self.time

    def run_until(self, t: float) -> float:
        """Step until the point at or past ``t`` (the stop time at most); return the time reached."""
        self._check_open()
        stop = self._cosim.stopTime
        tolerance = 1e-9 * self._cosim.stepSize
        if not (isinstance(t, (int, float)) and math.isfinite(t)):
            raise TimeError(f"run_until({t!r}): not a finite time")
        if t > stop + tolerance:
            raise TimeError(f"run_until({t:g}): past the stop time of {self._loaded.name!r}, {stop:g} s")
        if self.ended or t <= self.time + tolerance:
            return self.time
        self._advance(math.inf, t - tolerance, lambda at: at[1] >= t - tolerance)
        return self.time

    def _advance(self, step: int | float, t: float, arrived) -> None:
        self._gate.go(step, t)
        try:
            self._gate.wait(lambda: self._gate.at is not None and arrived(self._gate.at), lambda: self._over,
                            self._thread)
        except KeyboardInterrupt:
            self.close()
            raise
        self._raise_if_failed()

    def get(self, port: str) -> Any:
        """A port's value at the point the run stands at, as ``values.csv`` records it there (an
        output as its node stepped it, an input as routed for the next step); arrays as lists."""
        self._check_open()
        where = self._ports.get(port) if isinstance(port, str) else None
        if where is None:
            raise PortError(f"{port!r} is no port of {self._loaded.name!r} (write node.port)"
                            f"{did_you_mean([str(port)], self._ports)}")
        node, side, i = where
        values = self._relay.outputs if side == "outputs" else self._relay.router.inputs
        value = values[node][i]
        return list(value) if isinstance(value, (list, tuple)) else value

    def override(self, port: str, value: Any) -> None:
        """From the step the run takes next until :meth:`release`, input ``port`` (one a link
        feeds) sees ``value`` instead of what its links bring. Recorded (time, port, value) in
        ``events.jsonl``, and held through a rollback to a checkpoint as the project's
        ``scenario`` is."""
        self._manipulate(port, value)

    def release(self, port: str) -> None:
        """Input ``port`` follows its links again from the step the run takes next."""
        self._manipulate(port, None)

    def _manipulate(self, port: str, value: Any) -> None:
        from hycosim.core.scenario_checks import value_problem
        from hycosim.core.schema import ScenarioAction

        self._check_open()
        if self.ended:
            raise TimeError(f"the run of {self._loaded.name!r} is over: nothing is stepped any more")
        if not isinstance(port, str) or port not in self._ports:
            raise PortError(f"{port!r} is no port of {self._loaded.name!r} (write node.port)"
                            f"{did_you_mean([str(port)], self._ports)}")
        relay = self._relay
        target = relay.scenario.target(port)
        if target is None:
            raise OverrideError(f"{port} is no input a link feeds: an override takes the place of what links bring")
        if value is not None and (why := value_problem(target[2], value)) is not None:
            raise OverrideError(f"{port} {why}, not {value!r}")
        if value is None and not any(i == target[1] for i, _ in relay.router.pins.get(target[0], ())):
            raise OverrideError(f"{port} is not overridden: there is nothing to release")
        action = (ScenarioAction(t=self.time, override=port, value=value) if value is not None
                  else ScenarioAction(t=self.time, release=port))
        # The master stands at this point, its inputs routed: the step it takes next is on them.
        self._add_action(action)

    def set_parameter(self, parameter: str, value: Any) -> None:
        """From the step the run takes next, node parameter ``parameter`` (``node.name``, one the
        node's model declares tunable) is ``value``. Recorded (time, parameter, value) in
        ``events.jsonl``, and held through a rollback to a checkpoint as the project's
        ``scenario`` is."""
        from hycosim.core.frames import fits_tunable, tunable_value
        from hycosim.core.schema import ScenarioAction

        self._check_open()
        if self.ended:
            raise TimeError(f"the run of {self._loaded.name!r} is over: nothing is stepped any more")
        relay = self._relay
        tunable = relay.tunable()
        node, _, name = parameter.partition(".") if isinstance(parameter, str) else ("", "", "")
        if node not in tunable:
            raise ParameterError(f"{parameter!r} is no parameter of a stepping node of {self._loaded.name!r} "
                                 f"(write node.name){did_you_mean([node], sorted(tunable))}")
        if name not in tunable[node]:
            raise ParameterError(f"node {node!r} declares no tunable parameter {name!r} (its tunable parameters: "
                                 f"{', '.join(sorted(tunable[node])) or 'none'})")
        if not tunable_value(value) or not fits_tunable(value, tunable[node][name]):
            raise ParameterError(f"{parameter} is a {type(tunable[node][name]).__name__}, not {value!r}")
        self._add_action(ScenarioAction(t=self.time, parameter=parameter, value=value))

    def _add_action(self, action: Any) -> None:
        """An action at the point the run stands at: taken by the step it takes next (the master
        stands there, its inputs routed; a parameter is sent now), and kept in ``meta.json`` with
        ``--scenario``'s, where a resumed run finds it."""
        relay = self._relay
        relay.scenario.add(action)
        relay.apply_scenario(self.step_count, self.time)
        kept = relay.recorder.meta.setdefault("scenario", [])
        kept.append(action.model_dump(by_alias=True, exclude_none=True))
        relay.recorder.write_meta()

    def add_observer(self, observer: Any) -> None:
        """Tell ``observer`` (a :class:`hycosim.Observer`: :class:`hycosim.LastValues`,
        :class:`hycosim.TimeSeries` or your own) of every point the run records from the one it
        stands at on, of rollbacks to a checkpoint and of the run's end."""
        self._check_open()
        if self.ended:
            raise TimeError(f"the run of {self._loaded.name!r} is over: no point is left to observe")
        from hycosim.master.observers import missing_methods

        if missing := missing_methods(observer):
            raise SimulationError(f"{type(observer).__name__} is no observer: it lacks {', '.join(missing)}")
        self._relay.add_observer(observer)

    def stop(self) -> None:
        """Ask the run to stop at the next point it reaches (thread-safe: from another thread, a
        deadline's timer); a ``run_until`` under way returns there, and the run ends as stopped,
        every row recorded so far kept."""
        if self._relay is not None:
            self._relay.request_stop()
        self._gate.open_wide()

    def close(self) -> None:
        """End the run: one before its stop time is stopped at the point it stands at, every row
        recorded so far kept. A second call does nothing."""
        if self._closed:
            return
        self._closed = True
        if self._thread.is_alive():
            if self._relay is not None:
                self._relay.request_stop()
            self._gate.open_wide()
            # A step under way ends first (in process a step is a call into the models).
            self._thread.join(timeout=self._cosim.stepTimeout + 60.0)

    def __enter__(self) -> Simulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _check_open(self) -> None:
        if self._closed:
            raise ClosedError(f"the run of {self._loaded.name!r} is closed")

    def _raise_if_failed(self) -> None:
        if self._failure is not None:
            raise RunFailed(f"the run of {self._loaded.name!r} failed: {type(self._failure).__name__}: "
                            f"{self._failure}") from self._failure
        if self._result is not None and self._result[0] != 0:
            code, run_dir, message = self._result
            raise RunFailed(f"{message} (results so far: {run_dir})")
