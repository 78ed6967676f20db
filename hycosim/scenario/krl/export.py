"""``hycosim krl export RUN_DIR -o DIR``: a run's joint path as EthernetKRL files.

Writes ``<name>.xml`` (the EKI configuration), ``<name>.src`` (the KRL program of the
paper's Table 1) and ``frames.xml`` (the frame stream, one frame a line, ending with the
empty-A1 frame). The path is the robot's recorded joint angles up to the grasp (when
``robot.grasped`` first holds), one frame per macro step.

A frame is a move the controller starts at its T (Table 1's loop waits for T, then moves
towards the frame's point). The twin's robot started the move of step k at t_k and was at
its recorded point at t_(k+1), so the frame sent at t_k carries the point recorded at t_(k+1)
and the gripper command routed at step k: the controller is then where the twin was at
every step point. (Sent at its own time, each point left the robot a step behind: replayed
against the twin's own rod, one 60° trial closed 1.25 mm from the grasp point where the
co-simulation had closed 0.54 mm.) The first frame is the reset point, the program's XP1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from hycosim.core.folders import make_folder
from hycosim.core.run_files import MissingColumns, RunFileError, iter_csv_rows

from hycosim.scenario.krl.eki import EkiConfig, frame, krl_program
from hycosim.scenario.robot import kr6


class ExportError(RuntimeError):
    """A run directory without a robot path; names the file."""


@dataclass
class JointPath:
    """The robot's joint path as a run recorded it: times from its start, the six axes in degrees, the
    gripper command, and the row where it grasped (None: it did not)."""

    t: list[float]
    q_deg: list[list[float]]
    close: list[bool]
    grasp_index: int | None


def read_path(run_dir: Path, robot: str = "robot") -> JointPath:
    """The joint path of node ``robot`` in a run's ``values.csv``, up to the grasp; ExportError naming
    the file where it holds none."""
    path = run_dir / "values.csv"
    cols = [f"{robot}.q{i}" for i in range(1, 7)]
    flags = (f"{robot}.grasped", f"{robot}.grip_cmd")
    no_path = f"{path}: no joint path ({', '.join(cols)}) recorded for node {robot!r}"
    t, q, close, grasp = [], [], [], None
    t0 = None
    try:
        # Read up to the grasp only: the path ends there, however long the run went on.
        for i, r in enumerate(iter_csv_rows(path, lambda c: c == "t" or c in cols or c in flags,
                                            required=("t", *cols))):
            t0 = r["t"] if t0 is None else t0
            t.append(r["t"] - t0)
            q.append([math.degrees(r[c]) for c in cols])
            close.append((r.get(flags[1]) or 0.0) > 0.5)
            if (r.get(flags[0]) or 0.0) > 0.5:
                grasp = i
                break
    except MissingColumns as exc:
        raise ExportError(no_path if set(exc.columns) & set(cols) else str(exc)) from None
    except RunFileError as exc:
        raise ExportError(str(exc)) from None
    if not t:
        raise ExportError(no_path)
    return JointPath(t, q, close, grasp)


def export(run_dir: Path, out: Path, config: EkiConfig | None = None) -> dict[str, Path]:
    """Write the run's path as EthernetKRL files in ``out``: the EKI configuration, the KRL program and
    the frames to stream; the files by kind."""
    config = config or EkiConfig()
    jp = read_path(run_dir)
    make_folder(out)
    files = {"eki": out / f"{config.name}.xml", "krl": out / f"{config.name}.src", "frames": out / "frames.xml"}
    files["eki"].write_text(config.to_xml())
    files["krl"].write_text(krl_program(config, tuple(jp.q_deg[0]) if jp.q_deg else kr6.READY_DEG))
    lines = [frame(jp.q_deg[0], jp.t[0], jp.close[0])]
    lines += [frame(q_next, t, close) for t, close, q_next in zip(jp.t, jp.close, jp.q_deg[1:])]
    lines.append(frame(None))
    files["frames"].write_text("\n".join(lines) + "\n")
    return files
