"""The KR6 R700 robot scene as an FMI 2.0 co-simulation FMU (pythonfmu): the same RobotScene as the node.

Inputs: q_cmd1..6 (rad), grip_cmd, rod_angle. Outputs: q1..6, tcp_x/y/z,
tcp_roll/pitch/yaw (ZYX Euler, rad), dist, gap, grip_x/y/z, grasped, collision, reachable,
near_miss: the robot node's outputs (hycosim.scenario.robot.node). Parameters (fixed): rod geometry
(length, radius, pivot_x/y/z, grasp_distance) and the base position.
"""

import numpy as np
from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real

from hycosim.scenario.robot import kr6
from hycosim.scenario.robot.scene import RobotScene, SceneParams, euler_zyx
from hycosim.scenario.rod.bounded import BoundedReal
from hycosim.scenario.rod.model import LIMITS

_REAL_OUT = ("tcp_x", "tcp_y", "tcp_z", "tcp_roll", "tcp_pitch", "tcp_yaw", "dist", "gap", "grip_x", "grip_y",
             "grip_z")
_BOOL_OUT = ("grasped", "collision", "reachable", "near_miss")
_PARAMS = ("rod_length", "rod_radius", "pivot_x", "pivot_y", "pivot_z", "grasp_distance", "base_x", "base_y", "base_z")
_RANGES = {"rod_length": LIMITS["length"], "rod_radius": LIMITS["radius"], "grasp_distance": LIMITS["grasp_distance"],
           **{f"{at}_{c}": LIMITS["coordinate"] for at in ("pivot", "base") for c in "xyz"}}


class RobotScene6(Fmi2Slave):
    """The robot scene as an FMI 2.0 co-simulation FMU (pythonfmu): axis commands, the gripper command
    and the rod's angle in; axes, TCP, distance and contact flags out."""

    description = "hycosim KUKA KR6 R700 sixx cell with gripper and mirrored rod (MuJoCo)"
    author = "hycosim"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        d = SceneParams()
        self.rod_length, self.rod_radius, self.grasp_distance = d.rod_length, d.rod_radius, d.grasp_distance
        self.pivot_x, self.pivot_y, self.pivot_z = d.pivot
        self.base_x, self.base_y, self.base_z = d.base
        for name in _PARAMS:
            low, high = _RANGES[name]
            self.register_variable(BoundedReal(name, low, high, causality=Fmi2Causality.parameter,
                                               variability=Fmi2Variability.fixed))
        for i in range(6):
            setattr(self, f"q_cmd{i + 1}", float(kr6.READY[i]))
            self.register_variable(Real(f"q_cmd{i + 1}", causality=Fmi2Causality.input))
        self.grip_cmd = False
        self.rod_angle = 0.0
        self.register_variable(Boolean("grip_cmd", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete))
        self.register_variable(Real("rod_angle", causality=Fmi2Causality.input))
        self._build()
        for i in range(6):
            self.register_variable(Real(f"q{i + 1}", causality=Fmi2Causality.output, initial=Fmi2Initial.exact))
        for name in _REAL_OUT:
            self.register_variable(Real(name, causality=Fmi2Causality.output, initial=Fmi2Initial.exact))
        for name in _BOOL_OUT:
            self.register_variable(Boolean(name, causality=Fmi2Causality.output, variability=Fmi2Variability.discrete,
                                           initial=Fmi2Initial.exact))

    def _build(self):
        self.scene = RobotScene(SceneParams(
            base=(self.base_x, self.base_y, self.base_z), rod_length=self.rod_length, rod_radius=self.rod_radius,
            pivot=(self.pivot_x, self.pivot_y, self.pivot_z), grasp_distance=self.grasp_distance))
        self._publish(self.scene.outputs(False))

    def _publish(self, o):
        for i in range(6):
            setattr(self, f"q{i + 1}", float(o.q[i]))
        self.tcp_x, self.tcp_y, self.tcp_z = (float(v) for v in o.tcp)
        self.tcp_roll, self.tcp_pitch, self.tcp_yaw = euler_zyx(o.tcp_rot)
        self.dist, self.gap = float(o.distance), float(o.gap)
        self.grip_x, self.grip_y, self.grip_z = (float(v) for v in o.grip_target)
        self.grasped, self.collision, self.reachable, self.near_miss = o.grasped, o.collision, o.reachable, o.near_miss

    def _get_fmu_state(self):
        state = super()._get_fmu_state()
        state["_scene"] = self.scene.snapshot()
        return state

    def _set_fmu_state(self, state):
        state = dict(state)
        snap = state.pop("_scene")
        super()._set_fmu_state(state)  # the outputs as they were: recomputing them would move the reach seed
        self.scene.restore(snap)

    def exit_initialization_mode(self):
        """Build the scene from the parameters set during initialisation."""
        self._build()

    def do_step(self, current_time, step_size):
        """Step the scene over ``step_size`` on the inputs set, and publish its outputs."""
        q_cmd = np.array([getattr(self, f"q_cmd{i + 1}") for i in range(6)])
        self._publish(self.scene.step(step_size, q_cmd, bool(self.grip_cmd), self.rod_angle))
        return True
