"""The robot scene as a hycosim node.

Inputs: ``q_cmd1``…``q_cmd6`` (rad), ``grip_cmd`` (close when > 0.5), ``rod_angle``.
Outputs: ``q1``…``q6``, ``tcp_x/y/z`` and ``tcp_roll/pitch/yaw`` (ZYX Euler, rad), ``dist``
(TCP to the rod's grasp point, m), ``grasped``, ``collision``, ``reachable``, ``near_miss``,
``gap`` (jaw opening, m) and ``grip_x/y/z`` (where the held rod's grasp point goes).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hycosim.node import parameters as check
from hycosim.node.interface import Node, NodeContext, NodeModelError, pack_state, unpack_state
from hycosim.scenario.robot import kr6
from hycosim.scenario.robot.scene import RobotScene, SceneOutputs, SceneParams, euler_zyx, outputs_restore, outputs_snapshot
from hycosim.scenario.rod.model import LIMITS
from hycosim.scenario.rod.node import ROD_PARAMETERS, rod_parameter_problems, rod_params


# What scene_params reads.
SCENE_PARAMETERS = ROD_PARAMETERS | {"base", "check_reach"}


def scene_parameter_problems(parameters: dict[str, Any]) -> list[str]:
    """What is wrong with the scene's description in a node's ``parameters``: the rod's, the
    robot's base (x, y, z in m) and ``check_reach``."""
    return rod_parameter_problems(parameters) + check.problems(
        check.point(parameters, "base", within=LIMITS["coordinate"][1]), check.flag(parameters, "check_reach"))


def pose_problem(q0_deg: Any) -> str | None:
    """Why ``q0_deg`` is not six joint angles in degrees within the axes' limits (the words
    that follow the parameter's name), or None (a pose outside them is no robot's, and a
    state saved from it would not restore)."""
    if not (type(q0_deg) in (list, tuple) and len(q0_deg) == 6
            and all(type(v) in (int, float) and math.isfinite(v) for v in q0_deg)):
        return f" must be six joint angles in degrees, not {check.json_repr(q0_deg)}"
    for i, (v, (lo, hi)) in enumerate(zip(q0_deg, kr6.LIMITS_DEG)):
        if not lo <= v <= hi:
            return f": A{i + 1} = {v:g}° is outside its limits [{lo}, {hi}]°"
    return None


def scene_params(parameters: dict[str, Any]) -> SceneParams:
    """The robot scene's settings from a node's parameters (the rod's, the base, whether to check
    reach)."""
    rod = rod_params(parameters)
    return SceneParams(base=tuple(float(v) for v in parameters.get("base", (0.0, 0.0, 0.0))),
                       rod_length=rod.length, rod_radius=rod.radius, pivot=rod.pivot, grasp_distance=rod.grasp_distance,
                       check_reach=bool(parameters.get("check_reach", True)))


def scene_output_dict(o: SceneOutputs) -> dict[str, Any]:
    """A scene's outputs as the node's output ports have them, by name."""
    roll, pitch, yaw = euler_zyx(o.tcp_rot)
    out: dict[str, Any] = {f"q{i + 1}": float(o.q[i]) for i in range(6)}
    out.update(tcp_x=o.tcp[0], tcp_y=o.tcp[1], tcp_z=o.tcp[2], tcp_roll=roll, tcp_pitch=pitch, tcp_yaw=yaw,
               dist=o.distance, grasped=o.grasped, collision=o.collision, reachable=o.reachable,
               near_miss=o.near_miss, gap=o.gap, grip_x=o.grip_target[0], grip_y=o.grip_target[1],
               grip_z=o.grip_target[2])
    return out


def initial_pose(node: str, q0_deg: Any) -> np.ndarray:
    """The parameter ``q0_deg`` as a pose (rad); NodeModelError naming the node, the parameter
    and the axis unless it fits (:func:`pose_problem`)."""
    problem = pose_problem(q0_deg)
    if problem is not None:
        raise NodeModelError(f"robot node {node!r}: parameters.q0_deg{problem}")
    # radians() may round past a limit
    return np.clip(np.radians(np.asarray(q0_deg, dtype=float)), kr6.LIMITS[:, 0], kr6.LIMITS[:, 1])


class RobotNode(Node):
    """The robot scene as a Python node: it moves the KR6's axes towards their commands, closes the
    gripper as told, mirrors the rod at the angle it receives, and outputs the axes, the TCP, the
    distance to the grasp point and the contact flags."""

    PARAMETERS = SCENE_PARAMETERS | {"q0_deg"}
    INPUTS = frozenset({f"q_cmd{i + 1}" for i in range(6)} | {"grip_cmd", "rod_angle"})
    OUTPUTS = frozenset({f"q{i + 1}" for i in range(6)} | {
        "tcp_x", "tcp_y", "tcp_z", "tcp_roll", "tcp_pitch", "tcp_yaw", "dist", "grasped", "collision", "reachable",
        "near_miss", "gap", "grip_x", "grip_y", "grip_z"})

    @classmethod
    def parameter_problems(cls, parameters: dict[str, Any]) -> list[str]:
        pose = None if parameters.get("q0_deg") is None else pose_problem(parameters["q0_deg"])
        return scene_parameter_problems(parameters) + ([f"parameter 'q0_deg'{pose}"] if pose else [])

    def setup(self, ctx: NodeContext) -> None:
        self.scene = RobotScene(scene_params(ctx.parameters))
        q0 = ctx.parameters.get("q0_deg")
        if q0 is not None:
            self.scene.set_state(initial_pose(ctx.name, q0), kr6.GRIPPER_OPEN, 0.0)
        self.last = self.scene.outputs(False)

    def outputs(self) -> dict[str, Any]:
        return scene_output_dict(self.last)

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        q_cmd = np.array([float(inputs.get(f"q_cmd{i + 1}", self.scene.q[i])) for i in range(6)])
        self.last = self.scene.step(h, q_cmd, float(inputs.get("grip_cmd", 0.0)) > 0.5,
                                    float(inputs.get("rod_angle", 0.0)))

    @property
    def can_rollback(self) -> bool:
        return True

    def get_state(self) -> bytes:
        return pack_state({"scene": self.scene.snapshot(), "last": outputs_snapshot(self.last)})

    def set_state(self, state: bytes) -> None:
        s = unpack_state(state, {"scene", "last"})
        self.scene.restore(s["scene"])
        self.last = outputs_restore(s["last"])
