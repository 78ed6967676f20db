"""An emulated KUKA controller: the robot's EthernetKRL endpoint, facing the emulated physical rod.

``hycosim krl controller --eki FILE`` listens on TCP as the EKI endpoint configured in the
file, parses frames per its RECEIVE elements, and executes the KRL program of Table 1 on
its own robot model: reset to the first point, then for each frame wait for its time,
move towards the axes within the axis speed limits, close or open the gripper as told; an empty
A1 ends the program. Meanwhile the physical rod (a RodModel whose parameters differ from
the twin's) swings. The controller reports whether the gripper closed on the rod, when,
and how far the TCP was from the rod's grasp point, then waits for the next program.

Malformed XML, out-of-limit axes, a T outside the program's time (MAX_PROGRAM_S), a frame with
no end and a dropped connection are rejected with a message
(sent back where the connection still stands, and logged) and leave it running.
"""

from __future__ import annotations

import math
import socket
import threading
from dataclasses import asdict, dataclass, field
from xml.sax.saxutils import quoteattr

import numpy as np
import structlog

from hycosim.scenario.krl.eki import EkiConfig, EkiError, parse_frame
from hycosim.scenario.robot import kr6
from hycosim.scenario.robot.scene import RobotScene, SceneParams
from hycosim.scenario.rod.model import RodModel, RodParams
from hycosim.core.endpoints import listen_family

TICK = 0.001  # s: the controller's interpolation cycle, emulated
# A frame's T is a $TIMER value the program waits for. The emulation runs the wait tick by
# tick, so a T far ahead (a typo, 1e300) would hold the controller for good: frames past
# this bound are rejected. The paper's programs last 15-17 s; ours under one.
MAX_PROGRAM_S = 120.0
# A peer that never closes a frame must not grow the buffer without bound.
MAX_FRAME_BYTES = 1 << 20


@dataclass
class ProgramResult:
    """What one program did: whether and when the gripper closed on the rod, how far the TCP was from
    the grasp point then, how long it ran, the frames it took and the ones it rejected."""

    grasped: bool
    grasp_time_s: float | None
    grasp_error_mm: float | None
    execution_time_s: float
    frames: int
    rejected: list[str] = field(default_factory=list)

    def to_xml(self) -> str:
        """The result as the acknowledgement the controller sends back (``<Robot><Ack …/></Robot>``)."""
        err = "" if self.grasp_error_mm is None else f"{self.grasp_error_mm:.2f}"
        tg = "" if self.grasp_time_s is None else f"{self.grasp_time_s:.3f}"
        return (f'<Robot><Ack Result="{"grasped" if self.grasped else "missed"}" T="{tg}" Error_mm="{err}" '
                f'Exec_s="{self.execution_time_s:.3f}" Frames="{self.frames}" Rejected="{len(self.rejected)}"/></Robot>')


class Program:
    """One execution of the Table 1 program against the physical rod."""

    def __init__(self, rod: RodParams, scene: SceneParams):
        self.rod = RodModel(rod)
        self.scene = RobotScene(SceneParams(**{**scene.__dict__, "check_reach": False}))
        self.t = 0.0
        self.started = False
        self.target = self.scene.q.copy()
        self.close = False
        self.result = ProgramResult(False, None, None, 0.0, 0)

    def _tick(self) -> None:
        self.rod.advance(TICK)
        out = self.scene.step(TICK, self.target, self.close, self.rod.angle)
        self.t += TICK
        if out.grasped and not self.result.grasped:
            grasp_point = self.rod.outputs().grasp
            self.result.grasped = True
            self.result.grasp_time_s = self.t
            self.result.grasp_error_mm = 1000 * float(np.linalg.norm(out.tcp - grasp_point))

    def run_until(self, t: float) -> None:
        """Run the controller's cycle, and the rod with it, until ``t`` (or the grasp)."""
        while self.t < t - 1e-9 and not self.result.grasped:
            self._tick()

    def accept(self, q_deg: list[float], t: float, close: bool) -> None:
        """One frame of the program: the first moves the robot to its axes at once (the reset), each
        waits for its time ``t`` and then moves towards ``q_deg`` and closes or opens the gripper."""
        q = np.radians(q_deg)
        if not self.started:
            # PTP to the initial position (reset) before the rod is released: no time passes.
            self.scene.set_state(q, kr6.GRIPPER_OPEN, self.rod.angle)
            self.started = True
        self.run_until(t)  # WAIT FOR $TIMER >= T
        self.target, self.close = q, close
        self.result.frames += 1

    def finish(self, settle: float = 0.3) -> ProgramResult:
        """End the program after ``settle`` more seconds (the last move completes, the jaws finish
        closing) and return its result."""
        self.run_until(self.t + settle)  # the last move completes; the jaws finish closing
        self.result.execution_time_s = self.t
        return self.result


def check_limits(q_deg: list[float]) -> str | None:
    """Why axes ``q_deg`` (degrees) are out of the KR6's limits, or None."""
    for i, (v, (lo, hi)) in enumerate(zip(q_deg, kr6.LIMITS_DEG)):
        if not lo <= v <= hi:
            return f"A{i + 1}={v:.2f}° is outside its limits [{lo}, {hi}]°"
    return None


def check_time(t: float) -> str | None:
    """Why a frame's time ``t`` is outside a program's time, or None."""
    if not math.isfinite(t) or not 0.0 <= t <= MAX_PROGRAM_S:
        return f"T={t:g} s is outside a program's time [0, {MAX_PROGRAM_S:g}] s"
    return None


class EmulatedController:
    """The emulated controller (see the module's text): listens on its EKI port and runs each program it
    is sent, until :meth:`stop`."""

    def __init__(self, config: EkiConfig, rod: RodParams, scene: SceneParams | None = None,
                 host: str = "127.0.0.1", port: int | None = None):
        self.config = config
        self.rod = rod
        self.scene = scene or SceneParams(rod_length=rod.length, rod_radius=rod.radius, pivot=rod.pivot,
                                          grasp_distance=rod.grasp_distance)
        self.log = structlog.get_logger("krl.controller")
        self.listener = socket.create_server((host, config.port if port is None else port),
                                             family=listen_family(host))
        self.address = self.listener.getsockname()
        self.results: list[ProgramResult] = []
        self.errors: list[str] = []
        self._stop = threading.Event()

    def serve_forever(self) -> None:
        """Take connections one after another, each a program, until :meth:`stop`; a program that breaks
        a rule is rejected with a message and the controller goes on."""
        self.listener.settimeout(0.2)
        while not self._stop.is_set():
            try:
                conn, peer = self.listener.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            with conn:
                self.handle(conn, str(peer))

    def stop(self) -> None:
        """Stop taking programs and close the listening socket."""
        self._stop.set()
        self.listener.close()

    def _reject(self, conn: socket.socket | None, message: str, program: Program | None) -> None:
        self.errors.append(message)
        if program is not None:
            program.result.rejected.append(message)
        self.log.warning("rejected", reason=message)
        if conn is not None:
            try:
                # quoted: the reason may hold the frame's own text, '<' and '&' included
                conn.sendall(f"<Robot><Error Msg={quoteattr(message)}/></Robot>".encode())
            except OSError:
                pass

    def handle(self, conn: socket.socket, peer: str = "") -> ProgramResult | None:
        """Run one program from one connection; None if the connection dropped before its end."""
        conn.settimeout(30.0)
        program = Program(self.rod, self.scene)
        buffer = b""
        while True:
            try:
                chunk = conn.recv(65536)
            except (socket.timeout, OSError):
                chunk = b""
            if not chunk:
                self._reject(None, f"connection from {peer or 'the PC'} dropped before the program ended "
                                   f"({program.result.frames} frames executed)", program)
                return None
            buffer += chunk
            if b"</Robot>" not in buffer and len(buffer) > MAX_FRAME_BYTES:
                self._reject(conn, f"no frame end (</Robot>) in {len(buffer)} bytes from {peer or 'the PC'}: "
                                   "connection closed", program)
                return None
            while b"</Robot>" in buffer:
                raw, _, buffer = buffer.partition(b"</Robot>")
                text = raw.decode(errors="replace").strip() + "</Robot>"
                start = text.find("<Robot")
                if start < 0:
                    self._reject(conn, "malformed frame: no <Robot> element", program)
                    continue
                try:
                    fr = parse_frame(text[start:], self.config)
                except EkiError as exc:
                    self._reject(conn, str(exc), program)
                    continue
                if fr.q_deg is None:  # empty A1: EXIT the loop, end of program
                    result = program.finish()
                    self.results.append(result)
                    self.log.info("program ended", **asdict(result))
                    try:
                        conn.sendall(result.to_xml().encode())
                    except OSError:
                        pass
                    return result
                bad = check_limits(fr.q_deg) or check_time(fr.t)
                if bad:
                    self._reject(conn, f"frame {program.result.frames + 1}: {bad}", program)
                    continue
                program.accept(fr.q_deg, fr.t, fr.close)


def stream_program(host: str, port: int, frames_text: str, timeout: float = 60.0) -> str:
    """Send a frame stream to a controller and return its final answer (the Ack or an error)."""
    with socket.create_connection((host, port), timeout=timeout) as s:
        s.sendall(frames_text.encode())
        data = b""
        while b"Ack" not in data:
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
    return data.decode(errors="replace")


def parse_ack(text: str) -> dict:
    """The controller's acknowledgement in ``text`` as a dict (grasped, its time and error, the
    execution time, frames taken and rejected); ValueError where the text holds none."""
    import xml.etree.ElementTree as ET

    for part in text.split("</Robot>"):
        if "<Ack" in part:
            ack = ET.fromstring(part[part.find("<Robot"):] + "</Robot>").find("Ack")
            val = lambda k: float(ack.get(k)) if ack.get(k) else None  # noqa: E731
            return {"grasped": ack.get("Result") == "grasped", "grasp_time_s": val("T"),
                    "grasp_error_mm": val("Error_mm"), "execution_time_s": val("Exec_s"),
                    "frames": int(ack.get("Frames")), "rejected": int(ack.get("Rejected"))}
    raise ValueError(f"no Ack in the controller's answer: {text[:200]!r}")
