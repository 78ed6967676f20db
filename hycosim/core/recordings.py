"""What a run directory recorded of one node, read back to play it again (``"replay": RUN_DIR``).

A stepping node's outputs are the ``node.port`` columns of ``values.csv``, one row per
macro-step point. An asynchronous node's samples are the lines of ``samples.jsonl``, each
as the server received it: the node, the point ``point`` of the first macro step whose
routing could use it (it arrived while the server gathered that point), the sample's time
stamp and its values in the node's output order. The recorded project (``project.json``,
the copy the server keeps) says which ports a node had and at what step size it ran.

Every file here is a user's input: anything that does not fit is a :class:`RecordingError`
naming the run directory, the file and the line, never another exception.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from hycosim.core import json_text
from hycosim.core.schema import CoSimulation, Node, PortType, Project
from hycosim.core.run_files import RunFileError, finished_lines, iter_csv_rows

SAMPLES_FILE = "samples.jsonl"
VALUES_FILE = "values.csv"
PROJECT_FILE = "project.json"

_INTEGER = re.compile(r"[+-]?\d+")


def _shown(shape: tuple[int, ...] | None) -> str:
    return "none (a scalar)" if shape is None else str(list(shape))


class RecordingError(RuntimeError):
    """A recording that cannot be played for a node; the message says why."""


def encode_sample(node: str, point: int, t: float, values: list[Any]) -> str:
    """One line of ``samples.jsonl``: a sample of ``node`` received before point ``point``.
    Binary values go as hex; floats as Python writes them, so they read back exactly."""
    cells = [v.hex() if type(v) is bytes else v for v in values]
    return json.dumps({"node": node, "point": point, "t": t, "values": cells}) + "\n"


@dataclass(frozen=True)
class Sample:
    """A recorded sample: usable from macro-step point ``point``, taken at ``t``."""

    point: int
    t: float
    values: list[Any]


def _real(text: str) -> float | int:
    # A Real port may carry an integer on the wire; the CSV then holds it without a point.
    return int(text) if _INTEGER.fullmatch(text) else float(text)


def _boolean(text: str) -> bool:
    if text in ("1", "True", "true"):
        return True
    if text in ("0", "False", "false"):
        return False
    raise ValueError(f"{text[:20]!r} is not a Boolean")


def _binary(text: str) -> bytes:
    if text.startswith("<"):
        raise ValueError("only its length was recorded (values.csv holds Binary values of up to 32 bytes whole)")
    return bytes.fromhex(text)


_CELL = {PortType.REAL: _real, PortType.INTEGER: int, PortType.BOOLEAN: _boolean,
         PortType.STRING: str, PortType.BINARY: _binary}

# What a sample's JSON value may be for each port type (JSON has no bytes: Binary is hex).
_SAMPLE_TYPES: dict[PortType, tuple[type, ...]] = {
    PortType.REAL: (float, int), PortType.INTEGER: (int,), PortType.BOOLEAN: (bool,),
    PortType.STRING: (str,), PortType.BINARY: (str, list)}


class Recording:
    """A run directory's records, as far as a node's playback needs them."""

    def __init__(self, run_dir: Path):
        """Open ``run_dir`` and read the project it recorded; RecordingError if it is no run directory."""
        self.run_dir = run_dir
        if not run_dir.is_dir():
            raise RecordingError(f"replay: {run_dir} is not a folder (a run directory of hycosim is expected)")
        try:
            data = json_text.loads((run_dir / PROJECT_FILE).read_bytes())
        except (OSError, ValueError) as exc:
            raise RecordingError(f"replay: {run_dir / PROJECT_FILE} cannot be read ({exc}): a run directory holds "
                                 "the project it ran") from None
        try:
            self.project = Project.model_validate(data)
        except ValidationError as exc:
            raise RecordingError(f"replay: {run_dir / PROJECT_FILE} is not a project file "
                                 f"({exc.error_count()} errors, the first: {exc.errors()[0]['msg']})") from None

    def recorded_node(self, spec: Node) -> Node:
        """The recorded node of the same name; RecordingError if there is none."""
        for n in self.project.nodeLists:
            if n.nodeName == spec.nodeName:
                return n
        names = ", ".join(n.nodeName for n in self.project.nodeLists)
        raise RecordingError(f"replay: the run in {self.run_dir} has no node {spec.nodeName!r} (its nodes: {names})")

    def misfits(self, spec: Node, cosim: CoSimulation) -> list[str]:
        """Why the recording cannot be played as ``spec`` in a run stepping as ``cosim`` (empty if it can)."""
        recorded = self.recorded_node(spec)
        ours = self.project.coSimulation
        found = []
        if recorded.asynchronous != spec.asynchronous:
            found.append(f"{spec.nodeName!r} was {'' if recorded.asynchronous else 'not '}asynchronous there")
        theirs = {p.name: p for p in recorded.output}
        for p in spec.output:
            if p.name not in theirs:
                found.append(f"it recorded no output {p.name!r} of {spec.nodeName!r} "
                             f"(its outputs: {', '.join(theirs) or 'none'})")
            elif theirs[p.name].type != p.type:
                found.append(f"output {spec.nodeName}.{p.name} was {theirs[p.name].type.value} there, "
                             f"{p.type.value} here")
            elif theirs[p.name].shape != p.shape:
                found.append(f"output {spec.nodeName}.{p.name} had shape {_shown(theirs[p.name].shape)} there, "
                             f"{_shown(p.shape)} here")
        if ours.stepSize != cosim.stepSize:
            found.append(f"it stepped {ours.stepSize:g} s, this project {cosim.stepSize:g} s")
        if ours.startTime != cosim.startTime:
            found.append(f"it started at {ours.startTime:g} s, this project at {cosim.startTime:g} s")
        return found

    def require_fit(self, spec: Node, cosim: CoSimulation) -> None:
        """RecordingError naming every misfit (:meth:`misfits`), if there is one."""
        misfits = self.misfits(spec, cosim)
        if misfits:
            raise RecordingError(f"replay: the run in {self.run_dir} does not fit node {spec.nodeName!r}: "
                                 + "; ".join(misfits))

    def outputs(self, spec: Node) -> list[tuple[float, list[Any]]]:
        """The stepping node's recorded outputs, (t, values in ``spec``'s output order) per point."""
        path = self.run_dir / VALUES_FILE
        ports = [(p.columns(spec.nodeName), _CELL[p.type], p.shape is not None) for p in spec.output]
        columns = ["t", *(c for cols, _, _ in ports for c in cols)]
        rows: list[tuple[float, list[Any]]] = []
        try:
            for number, row in enumerate(iter_csv_rows(path, required=columns), start=2):
                try:
                    t = float(row["t"])
                    values = [[convert(row[c]) for c in cols] if array else convert(row[cols[0]])
                              for cols, convert, array in ports]
                except ValueError as exc:
                    raise RecordingError(f"replay: {path}: line {number}: {exc}") from None
                if not math.isfinite(t) or (rows and t <= rows[-1][0]):
                    raise RecordingError(f"replay: {path}: line {number}: time {row['t'][:30]!r} does not "
                                         "follow the line before")
                rows.append((t, values))
        except RunFileError as exc:
            raise RecordingError(f"replay: {exc}") from None
        if not rows:
            raise RecordingError(f"replay: {path} holds no macro step")
        return rows

    def samples(self, spec: Node) -> list[Sample]:
        """The asynchronous node's recorded samples in the order the server received them."""
        path = self.run_dir / SAMPLES_FILE
        if not path.is_file():
            raise RecordingError(f"replay: {path} does not exist: the run recorded no samples "
                                 "(recorded by a hycosim before samples were kept?)")
        recorded = self.recorded_node(spec)
        index = {p.name: i for i, p in enumerate(recorded.output)}
        ports = [(index.get(p.name, -1), p) for p in spec.output]
        found: list[Sample] = []
        try:
            for number, line in enumerate(finished_lines(path), start=1):
                try:
                    record = json_text.loads(line)
                except ValueError:
                    raise RecordingError(f"replay: {path}: line {number} is not JSON") from None
                if type(record) is not dict or record.get("node") != spec.nodeName:
                    if type(record) is dict and type(record.get("node")) is str:
                        continue  # another node's sample
                    raise RecordingError(f"replay: {path}: line {number} names no node")
                found.append(self._sample(record, ports, len(recorded.output), path, number,
                                          found[-1].point if found else 0))
        except RunFileError as exc:
            raise RecordingError(f"replay: {exc}") from None
        return found

    @staticmethod
    def _sample(record: dict[str, Any], ports: list[tuple[int, Any]], width: int, path: Path, number: int,
                last_point: int) -> Sample:
        point, t, values = record.get("point"), record.get("t"), record.get("values")
        if type(point) is not int or not last_point <= point < 1 << 62:
            raise RecordingError(f"replay: {path}: line {number}: point {str(point)[:30]} is not a step at or "
                                 f"after the line before's ({last_point})")
        if type(t) not in (float, int) or not math.isfinite(t):
            raise RecordingError(f"replay: {path}: line {number}: time {str(t)[:30]} is not a finite number")
        if type(values) is not list or len(values) != width:
            raise RecordingError(f"replay: {path}: line {number}: not {width} values, one per output")
        picked = []
        for i, port in ports:
            value = values[i] if i >= 0 else None
            if type(value) not in _SAMPLE_TYPES[port.type]:
                raise RecordingError(f"replay: {path}: line {number}: output {port.name!r} holds "
                                     f"{str(value)[:30]!r}, not a {port.type.value}")
            if port.type == PortType.BINARY and type(value) is str:
                try:
                    value = bytes.fromhex(value)
                except ValueError:
                    raise RecordingError(f"replay: {path}: line {number}: output {port.name!r} is not hex") from None
            if port.type == PortType.REAL:
                # JSON writes a whole Real as 0, which reads back as an int: a Real port plays a float.
                try:
                    value = float(value)
                except OverflowError:
                    raise RecordingError(f"replay: {path}: line {number}: output {port.name!r} holds "
                                         f"{str(value)[:30]}…, beyond any float") from None
            picked.append(value)
        return Sample(point, float(t), picked)
