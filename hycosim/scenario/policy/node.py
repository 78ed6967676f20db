"""The DDPG policy as a hycosim node: loads a checkpoint and acts at every macro step.

Inputs: ``rod_angle``, ``rod_omega``, ``grasp_x/y/z`` (from the rod), ``q1``…``q6``,
``tcp_x/y/z``, ``gap``, ``dist``, ``grasped`` (from the robot scene).
Outputs: ``q_cmd1``…``q_cmd6``, ``grip_cmd`` and ``infer_ms`` (the policy's inference time
for this step, so the run records it). Parameters: ``checkpoint`` (relative to the project
JSON; default the pretrained one shipped with hycosim) and the rod's parameters (for the
turning-point prediction, as for the rod node).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from hycosim.node.interface import Node, NodeContext, pack_state, unpack_state
from hycosim.scenario.policy.ddpg import load_policy
from hycosim.scenario.policy.features import (Predictor, TurningPoint, action_to_targets, aim_time, grip_reflex, missed,
                                     observe)
from hycosim.scenario.robot import kr6
from hycosim.scenario.robot.node import SCENE_PARAMETERS, scene_parameter_problems, scene_params
from hycosim.scenario.robot.scene import RobotScene, SceneParams
from hycosim.scenario.rod.model import RodModel
from hycosim.scenario.rod.node import rod_params

PRETRAINED = Path(__file__).with_name("pretrained") / "ddpg_grasp.pt"


class PolicyNode(Node):
    """The trained DDPG policy as a node: from the robot's axes and the rod's state it commands the axes
    and the gripper at each macro step, and says how long its inference took."""

    PARAMETERS = SCENE_PARAMETERS | {"checkpoint"}
    INPUTS = frozenset({f"q{i + 1}" for i in range(6)} | {
        "rod_angle", "rod_omega", "grasp_x", "grasp_y", "grasp_z", "tcp_x", "tcp_y", "tcp_z", "gap", "dist", "grasped"})
    OUTPUTS = frozenset({f"q_cmd{i + 1}" for i in range(6)} | {"grip_cmd", "infer_ms"})

    @classmethod
    def parameter_problems(cls, parameters: dict[str, Any]) -> list[str]:
        return scene_parameter_problems(parameters)  # (the rod and the cell it plans in)

    def setup(self, ctx: NodeContext) -> None:
        given = ctx.parameters.get("checkpoint")
        path = (ctx.project_dir / given) if given else PRETRAINED
        self.agent = load_policy(path)
        params = scene_params(ctx.parameters)
        self.rod_radius = params.rod_radius
        self.predictor = Predictor(RodModel(rod_params(ctx.parameters)),
                                   RobotScene(SceneParams(**{**params.__dict__, "check_reach": False})))
        self.q_cmd = kr6.READY.copy()
        self.grip = False
        self.aim: float | None = None  # the time of the turning point the last command goes for
        self.infer_ms = 0.0

    def outputs(self) -> dict[str, Any]:
        out: dict[str, Any] = {f"q_cmd{i + 1}": float(self.q_cmd[i]) for i in range(6)}
        out.update(grip_cmd=self.grip, infer_ms=self.infer_ms)
        return out

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        started = time.perf_counter()
        q = np.array([float(inputs[f"q{i + 1}"]) for i in range(6)])
        tcp = np.array([float(inputs[k]) for k in ("tcp_x", "tcp_y", "tcp_z")])
        grasp = np.array([float(inputs[k]) for k in ("grasp_x", "grasp_y", "grasp_z")])
        angle, omega = float(inputs["rod_angle"]), float(inputs["rod_omega"])
        gap = float(inputs["gap"])
        values = np.array([*q, *tcp, *grasp, angle, omega, gap])
        if not np.all(np.abs(values) <= np.finfo(np.float32).max):
            # Other nodes' outputs: a NaN would come out of the actor (which works in float32, so
            # a larger value is infinite there) as the robot's command. The command in flight is
            # held until the inputs are a state again.
            self.infer_ms = 1000 * (time.perf_counter() - started)
            return
        if float(inputs.get("grasped", 0.0)) > 0.5:
            self.grip = True  # hold what we have
        else:
            points = self.predictor.update(t, angle, omega, q)
            obs = observe(t, q, tcp, grasp, angle, omega, float(inputs["gap"]), points, self.aim)
            action = self.agent.act(obs)
            self.q_cmd = action_to_targets(action, points, q)
            self.aim = aim_time(action, points)
            if self.grip and missed(gap, self.rod_radius):
                self.grip = False
            # Decided on the values at t, the command reaches the robot at t + h: one step late.
            self.grip = self.grip or grip_reflex(t, tcp, gap, points, self.rod_radius, delay=1.5 * h)
        self.infer_ms = 1000 * (time.perf_counter() - started)

    # The prediction rod is reset from the inputs at each prediction: the predicted turning
    # points, the scene's reach seed and the commands carry over from one step to the next.
    @property
    def can_rollback(self) -> bool:
        return True

    def get_state(self) -> bytes:
        p = self.predictor
        points = [[tp.t, tp.angle, tp.q.tolist(), tp.ok, tp.grasp.tolist()] for tp in p.points]
        return pack_state({"scene": p.scene.snapshot(), "points": points, "predicted_at": p.predicted_at,
                           "q_cmd": self.q_cmd.tolist(), "grip": self.grip, "infer_ms": self.infer_ms,
                           "aim": self.aim})

    def set_state(self, state: bytes) -> None:
        s = unpack_state(state, {"scene", "points", "predicted_at", "q_cmd", "grip", "infer_ms", "aim"})
        q_cmd = np.asarray(s["q_cmd"], dtype=float)
        if q_cmd.shape != (6,) or type(s["points"]) is not list or not (s["aim"] is None or type(s["aim"]) is float and math.isfinite(s["aim"])):
            raise ValueError("not a state of the policy node")
        p = self.predictor
        p.scene.restore(s["scene"])
        p.points = [TurningPoint(float(t), float(a), np.asarray(q, dtype=float), bool(ok), np.asarray(g, dtype=float))
                    for t, a, q, ok, g in s["points"]]
        p.predicted_at = float(s["predicted_at"])
        self.q_cmd, self.grip, self.infer_ms = q_cmd, bool(s["grip"]), float(s["infer_ms"])
        self.aim = None if s["aim"] is None else float(s["aim"])
