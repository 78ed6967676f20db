"""What the policy sees and does, shared by the training environment and the policy node.

Observation (34 numbers, normalised by the agent's running statistics):

* the six joint angles (rad) and the TCP position (m);
* the rod's grasp-point position (m), angle (rad) and angular velocity (rad/s);
* the jaw opening (m);
* the next two turning points of the rod, predicted with the rod's own model: their angle
  (rad) and the time until each (s), and whether the robot can be there in time
  (travel time at the axis speed limits to the IK pose, minus the time left) — what a
  person catching a pendulum watches: where it will stop, and when;
* the IK joint angles that put the jaws across the rod at each of those two points;
* the time until the turning point the command in flight aims at (``NO_AIM`` before the
  first). An action takes effect one macro step after its observation, so that command is
  part of the state: without it the policy cannot tell whether to keep going for the point
  it chose or to switch. Switching mid-way carried the arm through the rod's sweep in 14 of
  the 16 failed grasps out of 100 of the reference controller's episodes at 60°.

Action (7 numbers in [-1, 1]): the robot's joint targets (the paper's "angular positions of
the robot's motion axes"), expressed in the frame the observation offers: the first number
picks the turning point to catch (≤ 0 the next, > 0 the one after; a point whose IK did not
converge is masked when the other's did), the other six offset
each axis from that point's IK pose by up to ±``RESIDUAL`` rad. Joint targets in absolute
terms proved too coarse for a 1 cm grasp after minutes of training; this keeps the policy's
output in joint space while the network only has to learn choices and corrections.

The jaws close by reflex, not by the policy, timed so that they meet the rod at a turning
point: when the TCP is within ``REFLEX_DISTANCE`` of where the rod's grasp point will be at
a predicted turning point, and that point is as far ahead as the jaws need to close plus
the delay before they start (a grasp 30 ms early or late at 60° misses the grasp point by
4 mm: the rod accelerates at 8 m/s² there). Jaws that closed on nothing open again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hycosim.scenario.robot import kr6
from hycosim.scenario.robot.controller import travel_time, turning_points
from hycosim.scenario.robot.scene import RobotScene
from hycosim.scenario.rod.model import RodModel

OBS_DIM = 34
ACT_DIM = 7
RESIDUAL_DEG = 3.0  # a checkpoint is trained for one scale: it is stored with it and checked
RESIDUAL = np.radians(RESIDUAL_DEG)
REFLEX_DISTANCE = 0.01  # m: the arm must be there already, not sweeping past
REPREDICT_EVERY = 0.1   # s
REPREDICT_NEAR = 0.25   # s: closer than this to the next turning point, re-predict every step
NO_AIM = 2.0            # s: the aim feature before any command (as for a point not predicted)


def action_to_targets(action: np.ndarray, points: list["TurningPoint"], q: np.ndarray) -> np.ndarray:
    """Joint targets from an action, given the predicted turning points (hold still if none)."""
    a = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
    base = aimed_point(a, points)
    if base is None:
        return np.asarray(q, dtype=float)
    target = base.q + a[1:] * RESIDUAL
    return np.clip(target, kr6.LIMITS[:, 0], kr6.LIMITS[:, 1])


def aimed_point(action: np.ndarray, points: list["TurningPoint"]) -> "TurningPoint | None":
    """The predicted turning point an action goes for (None when none is predicted).

    A choice of a point whose IK did not converge goes to the other point when that one's
    did (action masking): the pose of an unconverged point does not put the jaws across the
    rod, so going there cannot end in a grasp. Cloned policies kept choosing such a point
    after a missed grasp and ran out of time (see benchmarks/FINDINGS.md)."""
    if not points:
        return None
    chosen, other = (points[0], points[1:]) if action[0] <= 0 or len(points) < 2 else (points[1], points[:1])
    if not chosen.ok and other and other[0].ok:
        return other[0]
    return chosen


def aim_time(action: np.ndarray, points: list["TurningPoint"]) -> float | None:
    """The absolute time of the turning point an action goes for, for the next observation."""
    p = aimed_point(np.clip(np.asarray(action, dtype=float), -1.0, 1.0), points)
    return None if p is None else p.t


def choice_action(index: int) -> np.ndarray:
    """The action that goes for turning point ``index`` (0 or 1) with no correction."""
    a = np.zeros(ACT_DIM, dtype=np.float32)
    a[0] = -0.5 if index == 0 else 0.5
    return a


def grip_reflex(t: float, tcp: np.ndarray, gap: float, points: list["TurningPoint"], rod_radius: float,
                delay: float) -> bool:
    """Whether to start closing the jaws now (see the module docstring).

    ``delay``: seconds from this decision to the jaws starting to move, plus half a step so
    that the macro-step grid spreads the meeting around the turning point, not after it."""
    lead = kr6.closing_time(gap, rod_radius) + delay
    return any(0.0 <= p.t - t <= lead and float(np.linalg.norm(tcp - p.grasp)) < REFLEX_DISTANCE
               for p in points if p.ok)


def missed(gap: float, rod_radius: float) -> bool:
    """The jaws closed past the rod's diameter: they caught nothing and should open again."""
    return gap < 2 * rod_radius - 1e-3


@dataclass
class TurningPoint:
    """A turning point of the rod ahead: its time and angle, the IK pose that catches it there, whether
    the IK converged, and where the grasp point will be."""

    t: float       # absolute time
    angle: float
    q: np.ndarray  # IK pose to catch it there
    ok: bool       # IK converged
    grasp: np.ndarray  # where the rod's grasp point will be (m, world)


class Predictor:
    """The rod's next turning points and the poses to catch them, re-predicted every 0.1 s, and
    at every step in the last quarter second before a turning point: a corrected twin keeps
    converging on the real rod, and a pose predicted 0.1 s early misses it by millimetres."""

    def __init__(self, rod: RodModel, scene: RobotScene):
        self.rod = rod
        self.scene = scene
        self.points: list[TurningPoint] = []
        self.predicted_at = -math.inf

    def update(self, t: float, angle: float, omega: float, q: np.ndarray) -> list[TurningPoint]:
        """The next turning points at ``t`` from the rod's measured ``angle`` and ``omega`` and the
        robot's axes ``q``: predicted anew where the last prediction is stale, refined near a turning
        point, else as they were."""
        stale = not self.points or self.points[0].t < t or t - self.predicted_at >= REPREDICT_EVERY
        if not stale and self.points[0].t - t < REPREDICT_NEAR:
            self._refine_next(t, angle, omega)
        elif stale:
            found = turning_points(self.rod, angle, omega, 2.0)[:2]
            self.points = [self._point(t + dt, a, q) for dt, a in found]
            self.predicted_at = t
        return self.points

    def _refine_next(self, t: float, angle: float, omega: float) -> None:
        """Re-predict only the next turning point, over a horizon just past it, with IK from its pose."""
        first = self.points[0]
        found = turning_points(self.rod, angle, omega, first.t - t + 0.05)[:1]
        if found:
            dt, a = found[0]
            self.points[0] = self._point(t + dt, a, first.q)

    def _point(self, t_turn: float, angle: float, q0: np.ndarray) -> TurningPoint:
        ik = self.scene.reach(angle, q0=q0)
        ok = ik.position_error < 1e-3 and ik.rotation_error < math.radians(1)
        return TurningPoint(t_turn, angle, ik.q, ok, self.scene.grasp_point(angle))


def observe(t: float, q: np.ndarray, tcp: np.ndarray, grasp: np.ndarray, angle: float, omega: float, gap: float,
            points: list[TurningPoint], aim: float | None) -> np.ndarray:
    """The policy's observation vector: the robot's axes, TCP and the grasp point, the rod's angle,
    angular velocity and the gripper's gap; for the next two turning points their angle, the time
    to them and the slack left after the travel there, and their poses; then the time to the
    point aimed at (clipped)."""
    feats = [*q, *tcp, *grasp, angle, omega, gap]
    poses = []
    for i in range(2):
        if i < len(points):
            p = points[i]
            slack = (p.t - t) - travel_time(q, p.q) if p.ok else -1.0
            feats += [p.angle, p.t - t, slack]
            poses += list(p.q)
        else:
            feats += [0.0, 2.0, -1.0]
            poses += list(q)
    # Clipped: a point passed long ago and one far ahead say the same (go for another; wait).
    aimed = NO_AIM if aim is None else float(np.clip(aim - t, -0.5, NO_AIM))
    return np.asarray(feats + poses + [aimed], dtype=np.float32)
