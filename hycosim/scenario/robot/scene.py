"""The robot scene: KR6 R700 with gripper and the mirrored rod (the paper's Process Simulate side).

Per macro step: joint position servos move each axis towards its command within its
speed limit (and joint limits), the jaws close or open at ``FINGER_SPEED`` and stop on
the rod when it lies between them, the rod is set to the angle received from the rod
node, and MuJoCo's kinematics and collision detection give the outputs:

* ``grasped``: the gripper is closed on the rod (rod between the jaws, jaws at its diameter);
* ``collision``: robot against rod (jaws excepted), floor, or itself;
* ``reachable``: an IK solution puts the TCP on the rod's grasp point with the approach
  perpendicular to the swing plane and the jaws across the rod;
* ``near_miss``: the rod is within ``near_miss_radius`` of the TCP but not between the jaws.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from hycosim.scenario.robot import kr6
from hycosim.scenario.robot.ik import IkResult, solve_ik


@dataclass(frozen=True)
class SceneParams:
    """The cell: the robot's base, the rod's size, pivot and grasp point, and the distances that count
    as a near miss and a grasp."""

    base: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rod_length: float = 0.6
    rod_radius: float = 0.01
    pivot: tuple[float, float, float] = (0.62, 0.0, 1.0)
    grasp_distance: float = 0.4
    near_miss_radius: float = 0.05  # m
    grasp_band: float = 0.02        # m: how far off the jaw centre plane the rod may be
    grasp_tol: float = 0.01         # m: how far off centre the closing jaws still catch the rod
    check_reach: bool = True


@dataclass
class SceneOutputs:
    """The scene after a step: axes, TCP position and orientation, distance to the grasp point, the
    flags (grasped, collision, reachable, near miss), the jaws' gap and the grasp target."""

    q: np.ndarray
    tcp: np.ndarray
    tcp_rot: np.ndarray = field(repr=False)
    distance: float
    grasped: bool
    collision: bool
    reachable: bool
    near_miss: bool
    gap: float
    grip_target: np.ndarray = field(repr=False)


def outputs_snapshot(o: SceneOutputs) -> dict:
    """A SceneOutputs as plain lists and numbers (for a node's or an FMU's saved state)."""
    return {"q": o.q.tolist(), "tcp": o.tcp.tolist(), "tcp_rot": o.tcp_rot.tolist(), "distance": float(o.distance),
            "grasped": bool(o.grasped), "collision": bool(o.collision), "reachable": bool(o.reachable),
            "near_miss": bool(o.near_miss), "gap": float(o.gap), "grip_target": o.grip_target.tolist()}


def outputs_restore(snap: dict) -> SceneOutputs:
    """The SceneOutputs :func:`outputs_snapshot` gave."""
    return SceneOutputs(np.asarray(snap["q"], dtype=float), np.asarray(snap["tcp"], dtype=float),
                        np.asarray(snap["tcp_rot"], dtype=float).reshape(3, 3), float(snap["distance"]),
                        bool(snap["grasped"]), bool(snap["collision"]), bool(snap["reachable"]),
                        bool(snap["near_miss"]), float(snap["gap"]), np.asarray(snap["grip_target"], dtype=float))


def grasp_rotation(angle: float) -> np.ndarray:
    """Target TCP orientation for grasping the rod at ``angle``: approach +x, jaws across the rod."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=float)


class RobotScene:
    """The robot scene (see the module's text): the KR6 with its gripper and the mirrored rod in
    MuJoCo."""

    def __init__(self, params: SceneParams | None = None):
        self.p = params or SceneParams()
        p = self.p
        self.model = mujoco.MjModel.from_xml_string(kr6.scene_mjcf(p.base, p.rod_length, p.rod_radius, p.pivot,
                                                                  p.grasp_distance))
        self.data = mujoco.MjData(self.model)
        self._scratch = mujoco.MjData(self.model)
        self._tcp = self.model.site("tcp").id
        self._grasp = self.model.site("rod_grasp").id
        self._rod_q = self.model.joint("rod").qposadr[0]
        self._fl = self.model.joint("finger_l").qposadr[0]
        self._fr = self.model.joint("finger_r").qposadr[0]
        geom = self.model.geom
        self._rod_geom = geom("rod").id
        self._floor = geom("floor").id
        self._fingers = {geom("finger_l").id, geom("finger_r").id}
        self._robot_geoms = {i for i in range(self.model.ngeom)
                             if self.model.geom_bodyid[i] not in (0, self.model.body("rod").id)}
        self.q = kr6.READY.copy()
        self._reach_q = kr6.READY.copy()  # continuation: the last reach solution seeds the next
        self.gap = kr6.GRIPPER_OPEN
        self.holding = False  # jaws closed on the rod: it stays held until they open
        self.rod_angle = 0.0
        self._update()

    # --- stepping -------------------------------------------------------------------

    def step(self, h: float, q_cmd: np.ndarray, grip_close: bool, rod_angle: float) -> SceneOutputs:
        """Advance the servos and jaws by h towards their commands, with the rod at ``rod_angle``."""
        # Commands and the rod's angle are other nodes' outputs: a NaN or infinite one holds its
        # axis (or the rod) where it was, since a NaN taken into the pose stays there for good.
        cmd = np.asarray(q_cmd, dtype=float)
        target = np.clip(np.where(np.isfinite(cmd), cmd, self.q), kr6.LIMITS[:, 0], kr6.LIMITS[:, 1])
        # Clipped again: q + (limit − q) can land an ulp past the limit, and restore refuses that.
        self.q = np.clip(self.q + np.clip(target - self.q, -kr6.SPEEDS * h, kr6.SPEEDS * h),
                         kr6.LIMITS[:, 0], kr6.LIMITS[:, 1])
        if math.isfinite(rod_angle):
            self.rod_angle = float(rod_angle)
        self._set_pose()
        within, _, _ = self._rod_between_jaws()
        rod_gap = 2 * self.p.rod_radius
        if grip_close:
            # The rod stops the jaws only if it is between them while they are still wider
            # than it: jaws that closed on nothing cannot catch a rod swinging through them.
            caught = (within or self.holding) and self.gap >= rod_gap - 1e-9
            self.gap = max(rod_gap if caught else 0.0, self.gap - kr6.FINGER_SPEED * h)
        else:
            self.gap = min(kr6.GRIPPER_OPEN, self.gap + kr6.FINGER_SPEED * h)
            self.holding = False
        self._update()
        return self.outputs(grip_close)

    def snapshot(self) -> dict:
        """Everything a step reads, as plain lists and numbers (JSON and msgpack alike); the
        MuJoCo data follows from it (poses are set, not integrated)."""
        return {"q": self.q.tolist(), "reach_q": np.asarray(self._reach_q, dtype=float).tolist(),
                "gap": float(self.gap), "holding": bool(self.holding), "rod_angle": float(self.rod_angle)}

    def restore(self, snap: dict) -> None:
        """Set the state :meth:`snapshot` gave; ValueError if it is not a state of this scene."""
        q, reach_q = np.asarray(snap["q"], dtype=float), np.asarray(snap["reach_q"], dtype=float)
        gap, rod_angle = float(snap["gap"]), float(snap["rod_angle"])
        if (q.shape != (6,) or reach_q.shape != (6,) or not np.all(np.isfinite(reach_q))
                or not np.all((q >= kr6.LIMITS[:, 0]) & (q <= kr6.LIMITS[:, 1]))
                or not 0.0 <= gap <= kr6.GRIPPER_OPEN or not math.isfinite(rod_angle)):
            raise ValueError("not a state of this robot scene")
        self.q, self._reach_q = q, reach_q
        self.gap, self.holding, self.rod_angle = gap, bool(snap["holding"]), rod_angle
        self._update()

    def set_state(self, q: np.ndarray, gap: float, rod_angle: float) -> None:
        """Put the robot at axes ``q`` with the jaws ``gap`` apart and the rod at ``rod_angle``, holding
        nothing."""
        self.q = np.asarray(q, dtype=float).copy()
        self.gap = gap
        self.holding = False
        self.rod_angle = rod_angle
        self._update()

    def _set_pose(self) -> None:
        d = self.data
        d.qpos[:6] = self.q
        d.qpos[self._fl] = d.qpos[self._fr] = (kr6.GRIPPER_OPEN - self.gap) / 2
        d.qpos[self._rod_q] = self.rod_angle
        mujoco.mj_kinematics(self.model, d)

    def _update(self) -> None:
        self._set_pose()
        mujoco.mj_forward(self.model, self.data)

    # --- geometry -------------------------------------------------------------------

    @property
    def tcp(self) -> np.ndarray:
        """The TCP's position (m, world)."""
        return self.data.site_xpos[self._tcp].copy()

    @property
    def tcp_rot(self) -> np.ndarray:
        """The TCP's orientation, a 3×3 rotation matrix."""
        return self.data.site_xmat[self._tcp].reshape(3, 3).copy()

    def _rod_frame(self) -> tuple[np.ndarray, np.ndarray]:
        a = self.rod_angle
        return np.asarray(self.p.pivot, dtype=float), np.array([0.0, math.sin(a), -math.cos(a)])

    def _rod_between_jaws(self) -> tuple[bool, float, np.ndarray]:
        """Whether the rod lies between the open jaws; its distance from the TCP; where it is held."""
        c, u = self._rod_frame()
        p = self.tcp
        s = float(np.dot(p - c, u))
        w = p - (c + s * u)
        rot = self.tcp_rot
        approach, jaw = rot[:, 0], rot[:, 1]
        along_ok = 0.05 <= s <= self.p.rod_length
        # Inside the opening, or close enough to centre that the closing jaws centre it.
        across = abs(np.dot(w, jaw))
        within = (along_ok and abs(np.dot(w, approach)) <= self.p.grasp_band
                  and (across + self.p.rod_radius <= self.gap / 2 + 1e-9 or across <= self.p.grasp_tol))
        return within, float(np.linalg.norm(w)) if along_ok else math.inf, w

    def grip_target(self) -> np.ndarray:
        """Where the rod's grasp point goes when the gripper holds the rod (drives the rod node)."""
        c, _ = self._rod_frame()
        d = self.tcp - c
        d[0] = 0.0  # the rod stays on its hinge: project onto the swing plane
        n = np.linalg.norm(d)
        direction = d / n if n > 1e-9 else np.array([0.0, 0.0, -1.0])
        return c + self.p.grasp_distance * direction

    def collisions(self) -> list[tuple[str, str]]:
        """Contacts that count as collisions (the jaws touching the rod is grasping)."""
        found = []
        robot = self._robot_geoms
        for i in range(self.data.ncon):
            con = self.data.contact[i]
            g1, g2 = int(con.geom1), int(con.geom2)
            pair = {g1, g2}
            if self._rod_geom in pair and pair & self._fingers:
                continue
            if not pair & robot:
                continue  # rod against floor is not the robot's business
            found.append((self.model.geom(g1).name, self.model.geom(g2).name))
        return found

    def grasp_point(self, angle: float) -> np.ndarray:
        """Where the rod's grasp point is when the rod hangs at ``angle``."""
        return np.asarray(self.p.pivot, dtype=float) + self.p.grasp_distance * np.array(
            [0.0, math.sin(angle), -math.cos(angle)])

    def reach(self, angle: float | None = None, q0: np.ndarray | None = None, back_off: float = 0.0) -> IkResult:
        """IK for the TCP on the rod's grasp point (at ``angle``, default the current one),
        or ``back_off`` metres behind it along the approach (a pre-grasp pose)."""
        a = self.rod_angle if angle is None else angle
        target = self.grasp_point(a)
        target[0] -= back_off
        mujoco.mj_copyData(self._scratch, self.model, self.data)
        result = solve_ik(self.model, self._scratch, "tcp", target, grasp_rotation(a),
                          q0=self._reach_q if q0 is None else q0, limits=kr6.LIMITS, iterations=60)
        if result.converged:
            self._reach_q = result.q
        return result

    def outputs(self, grip_close: bool = False) -> SceneOutputs:
        """The scene's outputs as it stands (``grip_close``: the gripper is told to close, so the rod is
        held once the jaws meet it)."""
        within, rod_distance, _ = self._rod_between_jaws()
        # Once the jaws have closed on the rod it is held (the rod node follows the gripper,
        # one macro step behind): the grasp lasts until the jaws open.
        self.holding = bool(grip_close and abs(self.gap - 2 * self.p.rod_radius) <= 1e-6 and (within or self.holding))
        grasped = self.holding
        tcp = self.tcp
        distance = float(np.linalg.norm(tcp - self.data.site_xpos[self._grasp]))
        near_miss = bool(not within and rod_distance < self.p.near_miss_radius)
        reachable = True
        if self.p.check_reach:
            r = self.reach()
            reachable = bool(r.position_error < 2e-3 and r.rotation_error < math.radians(2))
        return SceneOutputs(self.q.copy(), tcp, self.tcp_rot, distance, grasped, bool(self.collisions()),
                            reachable, near_miss, self.gap, self.grip_target())


def euler_zyx(rot: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of a rotation matrix, ZYX convention."""
    pitch = math.asin(max(-1.0, min(1.0, -rot[2, 0])))
    return math.atan2(rot[2, 1], rot[2, 2]), pitch, math.atan2(rot[1, 0], rot[0, 0])
