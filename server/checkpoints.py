"""Checkpoints of a whole co-simulation, under the run directory.

``checkpoints/<step>/`` holds, for the macro-step point ``step``, every stepping node's
serialised state (``<node>.state``), the server's own state (``server.msgpack``: time, mode,
disarmed events, outputs, the inputs last routed, asynchronous histories, where each record
file ends) and ``manifest.json`` (the project's hash, and each file's size and SHA-256).
A checkpoint is written into a hidden folder and renamed into place: a folder named by a step
is complete, or a crash in the middle of its writing is told by its manifest. Only the
newest ``KEEP`` are kept.

Reading checks every file against the manifest and the state's shape: a damaged or truncated
checkpoint is named and the one before it used.
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
from typing import Any

import msgpack

from core import json_text
from server.interpolation import MAX_DEGREE, InputTrack

KEEP = 2
FOLDER = "checkpoints"
SERVER_FILE = "server.msgpack"
MANIFEST = "manifest.json"
# What a file of a checkpoint may be called (node names are of this kind): no path, no NUL.
_FILE_NAME = re.compile(r"[A-Za-z0-9_.\-]+")
# The record files whose ends a checkpoint holds (server.recorder's).
RECORD_FILES = {"values.csv", "timing.csv", "events.jsonl", "samples.jsonl"}

# The server's state: each key and the type it must have when read back.
_SERVER_KEYS = {"step": int, "t": float, "origin": float, "j": int, "mode": str, "disarmed": list,
                "outputs": dict, "inputs": dict, "histories": dict, "records": dict, "localised": dict,
                "h": float}  # the macro step to try next (an error-controlled step's size)


class CheckpointError(RuntimeError):
    """A checkpoint that cannot be read or written; the message names it and why."""


@dataclass
class Checkpoint:
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


def steps(run_dir: Path) -> list[int]:
    """The steps that have a checkpoint folder, oldest first."""
    root = run_dir / FOLDER
    if not root.is_dir():
        return []
    return sorted(int(p.name) for p in root.iterdir() if p.is_dir() and p.name.isdigit())


def read(path: Path, config_sha256: str | None = None) -> Checkpoint:
    """The checkpoint in ``path``, every file checked; CheckpointError naming what is wrong."""
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
    if type(server) is not dict or any(type(server.get(k)) is not tp for k, tp in _SERVER_KEYS.items()):
        raise CheckpointError(f"{path / SERVER_FILE} does not hold a server state")
    records = server["records"]
    if not (0 <= server["step"] < 1 << 62 and math.isfinite(server["h"]) and server["h"] > 0 and all(type(v) is int and v >= 0 for v in records.values())
            and set(records) == RECORD_FILES):
        raise CheckpointError(f"{path / SERVER_FILE} holds a step or record offsets out of range")
    for history in server["histories"].values():
        samples = history.get("samples") if type(history) is dict else None
        if type(samples) is not list or type(history.get("received")) is not int or not all(
                type(s) is list and len(s) == 2 and type(s[0]) in (int, float) and type(s[1]) is list for s in samples):
            raise CheckpointError(f"{path / SERVER_FILE} holds an asynchronous history that is not one")
    for name in ("outputs", "inputs"):
        if not all(type(v) is list for v in server[name].values()):
            raise CheckpointError(f"{path / SERVER_FILE} holds {name} that are not lists")
    if server.get("track") is not None:  # iterative coupling's interpolated inputs (server.interpolation)
        try:
            InputTrack(MAX_DEGREE, []).restore(server["track"])
        except ValueError as exc:
            raise CheckpointError(f"{path / SERVER_FILE}: {exc}") from None
    states = {}
    for node in manifest["nodes"]:
        if type(node) is not str or f"{node}.state" not in data:
            raise CheckpointError(f"{path}: the state of node {node!r} is missing")
        states[node] = data[f"{node}.state"]
    return Checkpoint(server["step"], path, server, states)


def latest(run_dir: Path, config_sha256: str | None = None,
           before: int | None = None) -> tuple[Checkpoint | None, list[str]]:
    """The newest readable checkpoint (before step ``before``, if given), and why each newer one was passed over."""
    passed: list[str] = []
    for step in reversed(steps(run_dir)):
        if before is not None and step >= before:
            continue
        try:
            return read(run_dir / FOLDER / str(step), config_sha256), passed
        except CheckpointError as exc:
            passed.append(str(exc))
    return None, passed
