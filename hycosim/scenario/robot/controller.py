"""A scripted reference controller: grasp the swinging rod at a predicted turning point.

It runs the rod's own model forward from the routed angle and angular velocity to find
the next turning points (where the rod is momentarily at rest), picks the first one the
robot can reach in time (IK with the jaws across the rod, travel time from the axis
speed limits), commands those joint angles, and closes the jaws just before the rod
arrives. It lets the grasp scenario run end to end before the learned policy exists,
and is the baseline the policy is compared with.

Inputs: ``rod_angle``, ``rod_omega``, ``q1``…``q6``, ``grasped``.
Outputs: ``q_cmd1``…``q_cmd6``, ``grip_cmd``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from hycosim.node.interface import Node, NodeContext, pack_state, unpack_state
from hycosim.scenario.robot import kr6
from hycosim.scenario.robot.node import SCENE_PARAMETERS, scene_parameter_problems, scene_params
from hycosim.scenario.robot.scene import RobotScene, SceneParams
from hycosim.scenario.rod.model import RodModel
from hycosim.scenario.rod.node import rod_params


# Ten times the rod's speed at the bottom of a fall from upright (about 10 rad/s): the inputs
# are another node's outputs, and no state of a swinging rod is faster.
MAX_OMEGA = 100.0


@dataclass
class Plan:
    """The reference controller's plan: the turning point it aims at (its time and the rod's angle
    there) and the joint target that catches the rod there."""

    t_turn: float      # absolute time of the turning point
    angle: float       # rod angle there
    q: np.ndarray      # joint target at the turning point


def turning_points(rod: RodModel, angle: float, omega: float, horizon: float) -> list[tuple[float, float]]:
    """(time from now, angle) of the rod's turning points within ``horizon`` seconds; none from a
    state no rod swings in (a NaN or infinite value, or faster than MAX_OMEGA)."""
    if not (math.isfinite(angle) and abs(omega) <= MAX_OMEGA):
        return []  # MuJoCo would reset the rod to its start, and predict from there
    rod.reset(math.remainder(angle, 2 * math.pi), omega)
    dt = rod.model.opt.timestep
    found = []
    w_prev = omega
    steps = int(horizon / dt)
    for i in range(1, steps + 1):
        rod.advance(dt)
        w = rod.omega
        if w_prev != 0.0 and (w_prev > 0) != (w > 0):
            frac = abs(w_prev) / (abs(w_prev) + abs(w))
            found.append(((i - 1 + frac) * dt, rod.angle))
        w_prev = w
    return found


def travel_time(q_from: np.ndarray, q_to: np.ndarray) -> float:
    """Seconds the slowest axis takes from ``q_from`` to ``q_to`` at the axes' speed limits."""
    return float(np.max(np.abs(q_to - q_from) / kr6.SPEEDS))


def plan_grasp(rod: RodModel, scene: RobotScene, t: float, angle: float, omega: float, q: np.ndarray,
               horizon: float = 3.0, margin: float = 0.15, min_angle: float = math.radians(3)) -> Plan | None:
    """The first turning point the robot can reach, in time, with the jaws across the rod."""
    for dt, a in turning_points(rod, angle, omega, horizon):
        if abs(a) < min_angle:
            continue  # a rod all but at rest: any point will do, but needs no turning point
        ik = scene.reach(a, q0=q)
        if not (ik.position_error < 1e-3 and ik.rotation_error < math.radians(1)):
            continue
        if travel_time(q, ik.q) + margin <= dt:
            return Plan(t + dt, a, ik.q)
    return None


class ReferenceController(Node):
    """Parameters: the rod's (as for the rod node), ``close_lead`` s before the turning point
    to start closing (default: the jaws' closing time plus half a step, so that they meet the
    rod at the turning point), ``replan_every`` s (0.1)."""

    PARAMETERS = SCENE_PARAMETERS | {"close_lead", "replan_every"}
    INPUTS = frozenset({f"q{i + 1}" for i in range(6)} | {"rod_angle", "rod_omega", "grasped"})
    OUTPUTS = frozenset({f"q_cmd{i + 1}" for i in range(6)} | {"grip_cmd"})

    @classmethod
    def parameter_problems(cls, parameters: dict[str, Any]) -> list[str]:
        return scene_parameter_problems(parameters)  # (the rod and the cell it plans in)

    def setup(self, ctx: NodeContext) -> None:
        self.rod = RodModel(rod_params(ctx.parameters))
        params = scene_params(ctx.parameters)
        self.scene = RobotScene(SceneParams(**{**params.__dict__, "check_reach": False}))
        lead = ctx.parameter("close_lead", None)
        self.close_lead = None if lead is None else float(lead)
        self.rod_radius = params.rod_radius
        self.replan_every = float(ctx.parameter("replan_every", 0.1))
        self.q_cmd = kr6.READY.copy()
        self.grip = False
        self.plan: Plan | None = None
        self.planned_at = -math.inf

    def outputs(self) -> dict[str, Any]:
        out: dict[str, Any] = {f"q_cmd{i + 1}": float(self.q_cmd[i]) for i in range(6)}
        out["grip_cmd"] = self.grip
        return out

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        if float(inputs.get("grasped", 0.0)) > 0.5:
            self.grip = True  # hold what we have
            return
        now = t + h
        q = np.array([float(inputs.get(f"q{i + 1}", self.q_cmd[i])) for i in range(6)])
        committed = self.plan is not None and self.plan.t_turn - now < 0.3
        if not committed and now - self.planned_at >= self.replan_every:
            self.plan = plan_grasp(self.rod, self.scene, t, float(inputs["rod_angle"]), float(inputs["rod_omega"]), q)
            self.planned_at = now
        if self.plan is None:
            return
        self.q_cmd = self.plan.q
        # The command output now takes effect at ``now``: the jaws need their closing time.
        lead = self.close_lead
        if lead is None:
            lead = kr6.closing_time(kr6.GRIPPER_OPEN, self.rod_radius) + h / 2
        self.grip = self.plan.t_turn - now <= lead
        if now > self.plan.t_turn + 0.2:  # missed it: open and plan again
            self.plan, self.grip = None, False

    # The planning rod is reset from the inputs at each plan: only the scene's reach seed,
    # the plan and the commands carry over from one step to the next.
    @property
    def can_rollback(self) -> bool:
        return True

    def get_state(self) -> bytes:
        plan = None if self.plan is None else [self.plan.t_turn, self.plan.angle, self.plan.q.tolist()]
        return pack_state({"scene": self.scene.snapshot(), "q_cmd": self.q_cmd.tolist(), "grip": self.grip,
                           "plan": plan, "planned_at": self.planned_at})

    def set_state(self, state: bytes) -> None:
        s = unpack_state(state, {"scene", "q_cmd", "grip", "plan", "planned_at"})
        self.scene.restore(s["scene"])
        q_cmd = np.asarray(s["q_cmd"], dtype=float)
        if q_cmd.shape != (6,):
            raise ValueError("not a state of the reference controller")
        plan = s["plan"]
        self.plan = None if plan is None else Plan(float(plan[0]), float(plan[1]), np.asarray(plan[2], dtype=float))
        self.q_cmd, self.grip, self.planned_at = q_cmd, bool(s["grip"]), float(s["planned_at"])
