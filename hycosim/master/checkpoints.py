"""Checkpoints of a whole co-simulation, under the run directory.

``checkpoints/<step>/`` holds, for the macro-step point ``step``, every stepping node's
serialised state (``<node>.state``), the server's own state (``server.msgpack``: time, mode,
disarmed events, outputs, the inputs last routed, asynchronous histories, where each record
file ends) and ``manifest.json`` (the project's hash, and each file's size and SHA-256).
A checkpoint is written into a hidden folder and renamed into place: a folder named by a step
is complete, or a crash in the middle of its writing is told by its manifest. Only the
newest ``KEEP`` are kept.

Reading checks every file against the manifest, the state's shape and that it fits the
project: a damaged, truncated or hand-edited checkpoint is named and the one before it used.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import msgpack
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from hycosim.core import frames, json_text
from hycosim.core.schema import Port, Project, array_misfit, wire_types
from hycosim.master.interpolation import MAX_DEGREE, InputTrack

KEEP = 2
FOLDER = "checkpoints"
SERVER_FILE = "server.msgpack"
MANIFEST = "manifest.json"
# What a file of a checkpoint may be called (node names are of this kind): no path, no NUL.
_FILE_NAME = re.compile(r"[A-Za-z0-9_.\-]+")
_STEP_NAME = re.compile(r"[0-9]{1,18}")
# The record files whose ends a checkpoint holds (server.recorder's).
RECORD_FILES = {"values.csv", "timing.csv", "events.jsonl", "samples.jsonl"}

_Finite = Annotated[float, Field(allow_inf_nan=False)]
_Count = Annotated[int, Field(ge=0, lt=1 << 62)]


class _History(BaseModel):
    """An asynchronous source's kept samples (server.async_sources.SampleHistory.snapshot)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    samples: list[list[Any]]  # [t, values], oldest first
    received: _Count

    @model_validator(mode="after")
    def _timed(self) -> "_History":
        if not all(len(s) == 2 and type(s[0]) in (int, float) and math.isfinite(s[0]) and type(s[1]) is list
                   for s in self.samples):
            raise ValueError("samples: each is [time, [values]] with a finite time")
        times = [s[0] for s in self.samples]
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ValueError("samples: their times do not rise")
        return self


class _ServerState(BaseModel):
    """The server's own state at a checkpoint, as the relay writes it (strict: no "1" for 1).
    Whether it fits the project (ports, their types, modes) :func:`misfit` tells."""

    model_config = ConfigDict(extra="forbid", strict=True)
    step: _Count
    t: _Finite
    origin: _Finite  # points lie on a grid origin + j·H from here
    j: _Count
    mode: str
    disarmed: list[str]
    outputs: dict[str, list[Any]]
    inputs: dict[str, list[Any]]
    histories: dict[str, _History]
    records: dict[str, _Count]  # where each record file ends
    localised: dict[str, Any]  # a located event's search, recorded with the switch it found
    h: Annotated[float, Field(gt=0, allow_inf_nan=False)]  # the macro step to try next
    # What the master algorithm keeps (MasterAlgorithm.checkpoint): JSON; iterative coupling's
    # interpolated inputs under "track" (master.interpolation checks them), a controlled step's "h".
    algorithm: dict[str, Any] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _consistent(self) -> "_ServerState":
        if set(self.records) != RECORD_FILES:
            raise ValueError(f"records: the ends of {', '.join(sorted(RECORD_FILES))} are expected")
        if self.j > self.step or self.origin > self.t:
            raise ValueError(f"step {self.step} at t={self.t} lies before its grid (origin {self.origin}, j {self.j})")
        try:
            json.dumps(self.localised, allow_nan=False)
        except (TypeError, ValueError):
            raise ValueError("localised: not JSON") from None
        try:
            json.dumps(self.algorithm, allow_nan=False)
        except (TypeError, ValueError):
            raise ValueError("algorithm: not JSON") from None
        return self


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be read or written; the message names it and why."""


@dataclass
class Checkpoint:
    """A checkpoint read back: the point it was taken at, its file, the server's state and each node's
    serialised state."""

    step: int
    path: Path
    server: dict[str, Any]
    states: dict[str, bytes]  # node → its serialised state


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def write(run_dir: Path, step: int, server: dict[str, Any], states: dict[str, bytes], config_sha256: str) -> Path:
    """Write a complete checkpoint for ``step`` and drop all but the newest KEEP; return its folder."""
    root = run_dir / FOLDER
    final = root / str(step)
    tmp = root / f".{step}.partial"
    try:
        root.mkdir(exist_ok=True)
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        files = {SERVER_FILE: msgpack.packb(server, use_bin_type=True)}
        files.update((f"{node}.state", data) for node, data in states.items())
        for name, data in files.items():
            (tmp / name).write_bytes(data)
        manifest = {"step": step, "t": server["t"], "config_sha256": config_sha256, "nodes": sorted(states),
                    "files": {name: {"size": len(data), "sha256": _sha(data)} for name, data in files.items()}}
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=1))
        if final.exists():  # the same point again, after a restore: the new one replaces it
            shutil.rmtree(final)
        os.replace(tmp, final)
    except OSError as exc:
        raise CheckpointError(f"cannot write checkpoint {final}: {exc.strerror or exc}") from None
    for old in steps(run_dir)[:-KEEP]:
        shutil.rmtree(root / str(old), ignore_errors=True)
    return final


def next_time(t: float, start: float, every: float | None) -> float:
    """The first checkpoint time after ``t``, on a grid of its own from ``start``: a run
    restored to a checkpoint takes the same ones again (never, without ``every``)."""
    every = every or math.inf
    return start + (math.floor((t - start) / every + 1e-9) + 1) * every


def steps(run_dir: Path) -> list[int]:
    """The steps that have a checkpoint folder, oldest first."""
    root = run_dir / FOLDER
    if not root.is_dir():
        return []
    # ASCII digits only: "²".isdigit() holds, and int() refuses it.
    return sorted(int(p.name) for p in root.iterdir() if p.is_dir() and _STEP_NAME.fullmatch(p.name))


def read(path: Path, config_sha256: str | None = None, project: Project | None = None) -> Checkpoint:
    """The checkpoint in ``path``, every file checked (and, given ``project``, that it fits it:
    :func:`misfit`); CheckpointError naming what is wrong."""
    try:
        manifest = json_text.loads((path / MANIFEST).read_bytes())
    except (OSError, ValueError) as exc:
        raise CheckpointError(f"{path}: no readable {MANIFEST} ({exc})") from None
    files = manifest.get("files") if type(manifest) is dict else None
    if type(files) is not dict or SERVER_FILE not in files or type(manifest.get("nodes")) is not list:
        raise CheckpointError(f"{path}: {MANIFEST} does not describe a checkpoint")
    if config_sha256 is not None and manifest.get("config_sha256") != config_sha256:
        raise CheckpointError(f"{path}: taken with another project file (config hash "
                              f"{str(manifest.get('config_sha256'))[:12]}…, this one {config_sha256[:12]}…)")
    data: dict[str, bytes] = {}
    for name, entry in files.items():
        if not _FILE_NAME.fullmatch(name) or name in (".", ".."):
            raise CheckpointError(f"{path}: {MANIFEST} names {name[:60]!r}, not a file of the checkpoint")
        try:
            raw = (path / name).read_bytes()
        except OSError as exc:
            raise CheckpointError(f"{path / name}: {exc.strerror or exc}") from None
        if type(entry) is not dict or len(raw) != entry.get("size"):
            raise CheckpointError(f"{path / name} is truncated or damaged ({len(raw)} bytes, "
                                  f"the manifest says {entry.get('size') if type(entry) is dict else '?'})")
        if _sha(raw) != entry.get("sha256"):
            raise CheckpointError(f"{path / name} is damaged (its SHA-256 differs from the manifest's)")
        data[name] = raw
    try:
        server = msgpack.unpackb(data[SERVER_FILE], raw=False, strict_map_key=False)
    except Exception:
        raise CheckpointError(f"{path / SERVER_FILE} is not msgpack") from None
    try:
        server = _ServerState.model_validate(server).model_dump()
    except ValidationError as exc:
        raise CheckpointError(f"{path / SERVER_FILE} does not hold a server state ({_first_problem(exc)})") from None
    track = server["algorithm"].get("track")
    if track is not None:  # iterative coupling's interpolated inputs (master.interpolation)
        try:
            InputTrack(MAX_DEGREE, []).restore(track)
        except ValueError as exc:
            raise CheckpointError(f"{path / SERVER_FILE}: {exc}") from None
    problem = misfit(server, project) if project is not None else None
    if problem is not None:
        raise CheckpointError(f"{path} does not fit the project: {problem}")
    states = {}
    for node in manifest["nodes"]:
        if type(node) is not str or f"{node}.state" not in data:
            raise CheckpointError(f"{path}: the state of node {node!r} is missing")
        states[node] = data[f"{node}.state"]
    return Checkpoint(server["step"], path, server, states)


def misfit(server: dict[str, Any], project: Project) -> str | None:
    """What makes a server state that :func:`read` took not one of ``project``'s runs (its
    ports and their types, mode, events, time, asynchronous sources), or None. The config hash
    says the same project file; this holds also for a checkpoint edited by hand."""
    for name in ("outputs", "inputs"):
        theirs = server[name]
        if set(theirs) != {n.nodeName for n in project.nodeLists}:
            return f"its {name} are of other nodes than the project's"
        for node in project.nodeLists:
            wrong = _wrong_values(theirs[node.nodeName], node.output if name == "outputs" else node.input)
            if wrong is not None:
                return f"its {name} of {node.nodeName}: {wrong}"
    if server["mode"] not in project.modes():
        return f"it is in mode {server['mode']!r}, which the project does not have"
    unknown = set(server["disarmed"]) - {e.name for e in project.events}
    if unknown:
        return f"it disarms event(s) {', '.join(sorted(unknown))[:200]}, which the project does not have"
    cosim = project.coSimulation
    slack = 1e-9 * max(1.0, abs(cosim.startTime), abs(cosim.stopTime))
    if not cosim.startTime - slack <= server["origin"] <= server["t"] <= cosim.stopTime + slack:
        return f"its time {server['t']:g} s lies outside the run's {cosim.startTime:g}-{cosim.stopTime:g} s"
    sources = {n.nodeName: n for n in project.async_nodes()}
    for node, history in server["histories"].items():
        if node not in sources:
            return f"it holds samples of {node[:64]!r}, which is no asynchronous node of the project"
        for _, values in history["samples"]:
            wrong = _wrong_values(values, sources[node].output)
            if wrong is not None:
                return f"a sample of {node}: {wrong}"
    return None


def _wrong_values(values: list[Any], ports: list[Port]) -> str | None:
    """What is wrong with ``values`` as one value for each of ``ports`` (their wire types), or None."""
    if len(values) != len(ports):
        return f"{len(values)} values for {len(ports)} ports"
    i = frames.first_misfit(values, (wire_types(p) for p in ports))
    if i is not None:
        return f"{ports[i].name} holds {type(values[i]).__name__} {frames.short(values[i])}, not a {ports[i].type.value}"
    for value, port in zip(values, ports):
        wrong = array_misfit(port, value) if port.shape is not None else None
        if wrong is not None:
            return f"{port.name} holds {wrong}"
    return None


def _first_problem(exc: ValidationError) -> str:
    e = exc.errors()[0]
    where = ".".join(str(p) for p in e["loc"])
    msg = e["msg"].removeprefix("Value error, ")
    return f"{where}: {msg}" if where else msg


def latest(run_dir: Path, config_sha256: str | None = None, before: int | None = None,
           project: Project | None = None) -> tuple[Checkpoint | None, list[str]]:
    """The newest readable checkpoint (before step ``before``, if given; fitting ``project``,
    if given), and why each newer one was passed over."""
    passed: list[str] = []
    for step in reversed(steps(run_dir)):
        if before is not None and step >= before:
            continue
        try:
            return read(run_dir / FOLDER / str(step), config_sha256, project), passed
        except CheckpointError as exc:
            passed.append(str(exc))
    return None, passed
