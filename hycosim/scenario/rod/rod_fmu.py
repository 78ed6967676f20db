"""The rod as an FMI 2.0 co-simulation FMU (pythonfmu): the same RodModel as the node.

Parameters (fixed): length, mass, radius, damping, pivot_x/y/z, grasp_distance,
initial_angle (rad), observer_gain. Inputs: driven, grip_x/y/z, meas_angle, meas_t (the
measurement's capture time), meas_valid. Outputs: angle, omega, grasp_x/y/z, tip_x/y/z.
It steps exactly as the rod node does (hycosim.scenario.rod.node): held, it follows the gripper; free,
the camera's measurement corrects it. State save/restore covers MuJoCo's state, so the
coordinator can roll it back.
"""

import math

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real

from hycosim.scenario.rod.bounded import BoundedReal
from hycosim.scenario.rod.model import LIMITS, RodModel, RodParams

_PARAMS = ("length", "mass", "radius", "damping", "pivot_x", "pivot_y", "pivot_z", "grasp_distance",
           "initial_angle", "observer_gain")
_RANGES = {**{name: LIMITS[name] for name in ("length", "mass", "radius", "damping", "grasp_distance",
                                               "observer_gain")},
           **{f"pivot_{c}": LIMITS["coordinate"] for c in "xyz"},
           "initial_angle": tuple(math.radians(v) for v in LIMITS["initial_angle_deg"])}
_INPUTS = ("grip_x", "grip_y", "grip_z", "meas_angle", "meas_t")
_OUTPUTS = ("angle", "omega", "grasp_x", "grasp_y", "grasp_z", "tip_x", "tip_y", "tip_z")


class Rod(Fmi2Slave):
    """The rod twin as an FMI 2.0 co-simulation FMU (pythonfmu): the driven flag, the gripper's position
    and the camera's measurement in; angle, angular velocity, grasp point and tip out."""

    description = "hycosim swinging wooden rod (MuJoCo)"
    author = "hycosim"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        d = RodParams()
        self.length, self.mass, self.radius, self.damping = d.length, d.mass, d.radius, d.damping
        self.pivot_x, self.pivot_y, self.pivot_z = d.pivot
        self.grasp_distance, self.initial_angle, self.observer_gain = d.grasp_distance, d.initial_angle, d.observer_gain
        for name in _PARAMS:
            low, high = _RANGES[name]
            self.register_variable(BoundedReal(name, low, high, causality=Fmi2Causality.parameter,
                                               variability=Fmi2Variability.fixed))
        self.driven = False
        self.meas_valid = False
        self.grip_x, self.grip_y, self.grip_z, self.meas_angle, self.meas_t = d.pivot[0], 0.0, 0.0, 0.0, 0.0
        self.register_variable(Boolean("driven", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete))
        self.register_variable(Boolean("meas_valid", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete))
        for name in _INPUTS:
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        self.model = None
        self._refresh(RodModel(self._params()))
        for name in _OUTPUTS:
            self.register_variable(Real(name, causality=Fmi2Causality.output, initial=Fmi2Initial.exact))

    def _params(self) -> RodParams:
        return RodParams(length=self.length, mass=self.mass, radius=self.radius, damping=self.damping,
                         pivot=(self.pivot_x, self.pivot_y, self.pivot_z), grasp_distance=self.grasp_distance,
                         initial_angle=self.initial_angle, observer_gain=self.observer_gain)

    def _refresh(self, model=None):
        if model is not None:
            self.model = model
        o = self.model.outputs()
        self.angle, self.omega = o.angle, o.omega
        self.grasp_x, self.grasp_y, self.grasp_z = (float(v) for v in o.grasp)
        self.tip_x, self.tip_y, self.tip_z = (float(v) for v in o.tip)

    def exit_initialization_mode(self):
        """Build the rod from the parameters set during initialisation."""
        # Parameters are final here.
        self._refresh(RodModel(self._params()))

    def do_step(self, current_time, step_size):
        """Step the rod over ``step_size`` on the inputs set (following the gripper while driven), and
        publish its outputs."""
        driven = bool(self.driven)
        if driven:
            self.model.set_gripper([self.grip_x, self.grip_y, self.grip_z])
        self.model.set_driven(driven)
        # Held by the gripper, the rod follows it; the camera corrects the free swing only.
        if not driven and self.meas_valid:
            self.model.correct(self.meas_angle, step_size, self.meas_t)
        self.model.advance(step_size)
        self._refresh()
        return True

    def _get_fmu_state(self):
        state = super()._get_fmu_state()
        state["_rod"] = self.model.snapshot()
        return state

    def _set_fmu_state(self, state):
        state = dict(state)
        snap = state.pop("_rod")
        super()._set_fmu_state(state)
        self.model.restore(snap)
        self._refresh()
