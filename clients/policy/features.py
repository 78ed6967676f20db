"""What the policy sees and does, shared by the training environment and the policy node.

Observation (33 numbers, normalised by the agent's running statistics):

* the six joint angles (rad) and the TCP position (m);
* the rod's grasp-point position (m), angle (rad) and angular velocity (rad/s);
* the jaw opening (m);
* the next two turning points of the rod, predicted with the rod's own model: their angle
  (rad) and the time until each (s), and whether the robot can be there in time
  (travel time at the axis speed limits to the IK pose, minus the time left) — what a
  person catching a pendulum watches: where it will stop, and when;
* the IK joint angles that put the jaws across the rod at each of those two points.

Action (7 numbers in [-1, 1]): the robot's joint targets (the paper's "angular positions of
the robot's motion axes"), expressed in the frame the observation offers: the first number
picks the turning point to catch (≤ 0 the next, > 0 the one after), the other six offset
each axis from that point's IK pose by up to ±``RESIDUAL`` rad. Joint targets in absolute
terms proved too coarse for a 1 cm grasp after minutes of training; this keeps the policy's
output in joint space while the network only has to learn choices and corrections.

The jaws close by reflex, not by the policy: when the rod's grasp point is within
``REFLEX_DISTANCE`` of the TCP and the rod has all but stopped (a turning point).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clients.robot import kr6
from clients.robot.controller import travel_time, turning_points
from clients.robot.scene import RobotScene
from clients.rod.model import RodModel

OBS_DIM = 33
ACT_DIM = 7
RESIDUAL = np.radians(15.0)
REFLEX_DISTANCE = 0.03  # m
REFLEX_OMEGA = 1.2      # rad/s
REPREDICT_EVERY = 0.1   # s


def action_to_targets(action: np.ndarray, points: list["TurningPoint"], q: np.ndarray) -> np.ndarray:
    """Joint targets from an action, given the predicted turning points (hold still if none)."""
    a = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
    if not points:
        return np.asarray(q, dtype=float)
    base = points[0] if a[0] <= 0 or len(points) < 2 else points[1]
    target = base.q + a[1:] * RESIDUAL
    return np.clip(target, kr6.LIMITS[:, 0], kr6.LIMITS[:, 1])


def choice_action(index: int) -> np.ndarray:
    """The action that goes for turning point ``index`` (0 or 1) with no correction."""
    a = np.zeros(ACT_DIM, dtype=np.float32)
    a[0] = -0.5 if index == 0 else 0.5
    return a


def grip_reflex(distance: float, omega: float) -> bool:
    return distance < REFLEX_DISTANCE and abs(omega) < REFLEX_OMEGA


@dataclass
class TurningPoint:
    t: float       # absolute time
    angle: float
    q: np.ndarray  # IK pose to catch it there
    ok: bool       # IK converged


class Predictor:
    """The rod's next turning points and the poses to catch them, re-predicted at most every 0.1 s."""

    def __init__(self, rod: RodModel, scene: RobotScene):
        self.rod = rod
        self.scene = scene
        self.points: list[TurningPoint] = []
        self.predicted_at = -math.inf

    def update(self, t: float, angle: float, omega: float, q: np.ndarray) -> list[TurningPoint]:
        stale = not self.points or self.points[0].t < t or t - self.predicted_at >= REPREDICT_EVERY
        if stale:
            found = turning_points(self.rod, angle, omega, 2.0)[:2]
            self.points = []
            for dt, a in found:
                ik = self.scene.reach(a, q0=q)
                ok = ik.position_error < 1e-3 and ik.rotation_error < math.radians(1)
                self.points.append(TurningPoint(t + dt, a, ik.q, ok))
            self.predicted_at = t
        return self.points


def observe(t: float, q: np.ndarray, tcp: np.ndarray, grasp: np.ndarray, angle: float, omega: float, gap: float,
            points: list[TurningPoint]) -> np.ndarray:
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
    return np.asarray(feats + poses, dtype=np.float32)
