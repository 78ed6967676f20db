"""The rod as a hycosim node (the same RodModel the FMU and the RL environment use).

Inputs: ``driven`` (also set by the coordinator's mode), ``grip_x/y/z`` (where the gripper
holds the grasp point), ``meas_angle``, ``meas_t`` (capture time, optional) and
``meas_valid`` (the camera's measurement).
Outputs: ``angle``, ``omega``, ``grasp_x/y/z``, ``tip_x/y/z``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hycosim.node import parameters as check
from hycosim.node.interface import Node, NodeContext, pack_state, unpack_state
from hycosim.scenario.rod.model import LIMITS, RodModel, RodParams


# What rod_params reads: the rod node's parameters, and part of every grasp node's (they
# share the rod's description so that a project states it once per node alike).
ROD_PARAMETERS = frozenset({"length", "mass", "radius", "damping", "pivot", "grasp_distance", "initial_angle_deg",
                            "initial_omega", "observer_gain"})


def rod_parameter_problems(parameters: dict[str, Any]) -> list[str]:
    """What is wrong with the rod's description in a node's ``parameters`` (hycosim.node.parameters)."""

    def within(name: str) -> str | None:
        low, high = LIMITS[name]
        return check.number(parameters, name, at_least=low, at_most=high)

    found = check.problems(
        within("length"), within("mass"), within("radius"), within("damping"),
        check.point(parameters, "pivot", within=LIMITS["coordinate"][1]),
        check.number(parameters, "grasp_distance", above=0.0, at_most=LIMITS["grasp_distance"][1]),
        within("initial_angle_deg"), within("initial_omega"), within("observer_gain"))
    if not found:  # the grasp point and the rod's thickness lie on the rod
        p = rod_params(parameters)
        if p.grasp_distance > p.length:
            found.append(f"parameter 'grasp_distance' ({p.grasp_distance:g} m) lies beyond the rod's 'length' "
                         f"({p.length:g} m)")
        if 2 * p.radius >= p.length:
            found.append(f"parameter 'radius' ({p.radius:g} m) is half the rod's 'length' ({p.length:g} m) or "
                         "more: a rod longer than it is thick")
    return found


def rod_params(parameters: dict[str, Any]) -> RodParams:
    """RodParams from a node's ``parameters`` (angles in degrees, as people write them)."""
    d = RodParams()
    return RodParams(
        length=float(parameters.get("length", d.length)),
        mass=float(parameters.get("mass", d.mass)),
        radius=float(parameters.get("radius", d.radius)),
        damping=float(parameters.get("damping", d.damping)),
        pivot=tuple(float(v) for v in parameters.get("pivot", d.pivot)),
        grasp_distance=float(parameters.get("grasp_distance", d.grasp_distance)),
        initial_angle=math.radians(float(parameters.get("initial_angle_deg", math.degrees(d.initial_angle)))),
        initial_omega=float(parameters.get("initial_omega", d.initial_omega)),
        observer_gain=float(parameters.get("observer_gain", d.observer_gain)),
    )


class RodNode(Node):
    """The rod twin as a Python node: it swings freely, or follows the gripper while the event drives
    it, and is pulled towards the camera's measurements where its observer gain says so; it outputs its
    angle, angular velocity, grasp point and tip."""

    PARAMETERS = ROD_PARAMETERS
    INPUTS = frozenset({"driven", "grip_x", "grip_y", "grip_z", "meas_angle", "meas_t", "meas_valid"})
    OUTPUTS = frozenset({"angle", "omega", "grasp_x", "grasp_y", "grasp_z", "tip_x", "tip_y", "tip_z"})

    @classmethod
    def parameter_problems(cls, parameters: dict[str, Any]) -> list[str]:
        return rod_parameter_problems(parameters)

    def setup(self, ctx: NodeContext) -> None:
        self.rod = RodModel(rod_params(ctx.parameters))
        self.mode_driven = False

    def set_mode(self, mode: str, driven: bool) -> None:
        self.mode_driven = driven

    def outputs(self) -> dict[str, Any]:
        o = self.rod.outputs()
        return {"angle": o.angle, "omega": o.omega, "grasp_x": o.grasp[0], "grasp_y": o.grasp[1],
                "grasp_z": o.grasp[2], "tip_x": o.tip[0], "tip_y": o.tip[1], "tip_z": o.tip[2]}

    def step(self, t: float, h: float, inputs: dict[str, Any]) -> None:
        driven = self.mode_driven or float(inputs.get("driven", 0.0)) > 0.5
        if driven:
            pivot = self.rod.p.pivot
            self.rod.set_gripper(np.array([float(inputs.get("grip_x", pivot[0])), float(inputs.get("grip_y", 0.0)),
                                           float(inputs.get("grip_z", 0.0))]))
        self.rod.set_driven(driven)
        # Held by the gripper, the rod follows the gripper (s_A = g_B(s_B)); the camera's view
        # of the physical rod corrects the free swing only.
        if not driven and float(inputs.get("meas_valid", 0.0)) > 0.5:
            at = inputs.get("meas_t")
            self.rod.correct(float(inputs["meas_angle"]), h, None if at is None else float(at))
        self.rod.advance(h)

    @property
    def can_vary_step(self) -> bool:
        return False  # it advances whole MuJoCo steps: a step of another length would drift its clock

    @property
    def can_rollback(self) -> bool:
        return True

    def get_state(self) -> bytes:
        return pack_state({"rod": self.rod.snapshot(), "driven": self.mode_driven})

    def set_state(self, state: bytes) -> None:
        s = unpack_state(state, {"rod", "driven"})
        self.rod.restore(s["rod"])
        self.mode_driven = bool(s["driven"])
