"""The swinging wooden rod in MuJoCo (the paper's Adams model).

A uniform rod (cylinder) hangs from a hinge whose axis is world x, so it swings in the
y–z plane: at angle φ (0 hanging down, positive about +x) a point s metres down the rod is
at pivot + s·(0, sin φ, −cos φ).

Free, the rod follows its own dynamics (implicitfast integrator, 1 ms steps, joint
damping). Driven, a ``connect`` equality ties the grasp point to a mocap body placed at
the gripper: the rod's state is never reset, so angle and angular velocity are continuous
at both switches (only the forces change). A measurement of the real rod's angle
corrects the twin through a Luenberger observer on (φ, ω) with error dynamics
ë + 2l·ė + l²·e = 0 (critically damped, rate ``observer_gain`` l in 1/s; 0 turns it off).
A measurement carries its capture time: it is compared with the twin's own angle at that
time (kept for the last second), so camera latency does not bias the correction. Any finite
sample is taken (the error modulo a turn); later good ones bring the twin onto the rod.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import mujoco
import numpy as np


@dataclass(frozen=True)
class RodParams:
    """The rod: its size, mass and hinge damping, where it hangs and where it is grasped, its release
    state, MuJoCo's time step, the observer's gain (0: no correction by the camera) and gravity."""

    length: float = 0.6          # m
    mass: float = 0.3            # kg
    radius: float = 0.01         # m
    damping: float = 0.002       # N·m·s/rad at the hinge
    pivot: tuple[float, float, float] = (0.62, 0.0, 1.0)  # m, world (the robot base at the origin)
    grasp_distance: float = 0.4   # m from the pivot along the rod
    initial_angle: float = math.radians(40.0)  # rad
    initial_omega: float = 0.0   # rad/s
    timestep: float = 0.001      # s, MuJoCo's integrator step
    observer_gain: float = 0.0   # 1/s; 0: no correction
    gravity: float = 9.81

    def inertia_about_pivot(self) -> float:
        """Uniform solid cylinder about a transverse axis through one end."""
        return self.mass * (3 * self.radius ** 2 + self.length ** 2) / 12 + self.mass * (self.length / 2) ** 2


# What a rod in a robot's cell may be, far on both sides (SI units; "coordinate": each of the
# pivot's, and of the robot's base, in m): beyond, MuJoCo refuses the body (mass or inertia
# under 1e-15) or its millisecond steps diverge. The rod and robot nodes check their
# parameters against them, and the scene FMUs declare them as their parameters' min and max.
LIMITS = {"length": (1e-3, 100.0), "mass": (1e-3, 1e4), "radius": (1e-4, 1.0), "damping": (0.0, 1e3),
          "coordinate": (-100.0, 100.0), "grasp_distance": (0.0, 100.0), "initial_angle_deg": (-180.0, 180.0),
          "initial_omega": (-100.0, 100.0), "observer_gain": (0.0, 1e3)}


def rod_mjcf(p: RodParams, name: str = "rod") -> str:
    """MJCF of the rod scene: pivot, hinge, cylinder, grasp and tip sites, and the gripper mocap."""
    px, py, pz = p.pivot
    return f"""
<mujoco model="{name}">
  <option timestep="{p.timestep}" integrator="implicitfast" gravity="0 0 {-p.gravity}"/>
  <worldbody>
    <body name="rod" pos="{px} {py} {pz}">
      <joint name="hinge" type="hinge" axis="1 0 0" damping="{p.damping}"/>
      <geom name="rod" type="cylinder" fromto="0 0 0 0 0 {-p.length}" size="{p.radius}" mass="{p.mass}"
            rgba="0.85 0.1 0.1 1" contype="0" conaffinity="0"/>
      <site name="grasp" pos="0 0 {-p.grasp_distance}" size="0.005"/>
      <site name="tip" pos="0 0 {-p.length}" size="0.005"/>
    </body>
    <body name="gripper" mocap="true" pos="{px} {py} {pz - p.grasp_distance}"/>
  </worldbody>
  <equality>
    <connect name="grip" body1="rod" body2="gripper" anchor="0 0 {-p.grasp_distance}" active="false"
             solref="0.02 1"/>
  </equality>
</mujoco>
"""


@dataclass
class RodOutputs:
    """The rod's state: angle, angular velocity, and where its grasp point and tip are (m, world)."""

    angle: float
    omega: float
    grasp: np.ndarray = field(repr=False)
    tip: np.ndarray = field(repr=False)


class RodModel:
    """One rod simulation; :meth:`advance` integrates a macro step."""

    def __init__(self, params: RodParams | None = None):
        self.p = params or RodParams()
        self.model = mujoco.MjModel.from_xml_string(rod_mjcf(self.p))
        self.data = mujoco.MjData(self.model)
        self._hinge = self.model.joint("hinge").qposadr[0]
        self._dof = self.model.joint("hinge").dofadr[0]
        self._grasp = self.model.site("grasp").id
        self._tip = self.model.site("tip").id
        self._eq = self.model.equality("grip").id
        self._history: deque[tuple[float, float]] = deque(maxlen=1000)
        self._last_measurement = -math.inf
        # Measurements captured at a time the twin had not reached when they came, oldest first.
        self._pending: deque[tuple[float, float]] = deque(maxlen=256)
        self.reset(self.p.initial_angle, self.p.initial_omega)

    def reset(self, angle: float, omega: float = 0.0) -> None:
        """Put the rod at ``angle`` with angular velocity ``omega``, at time zero, free."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[self._hinge] = angle
        self.data.qvel[self._dof] = omega
        self.data.eq_active[self._eq] = 0
        mujoco.mj_forward(self.model, self.data)
        self._history.clear()
        self._history.append((self.time, self.angle))
        self._last_measurement = -math.inf
        self._pending.clear()

    @property
    def angle(self) -> float:
        """The rod's angle from hanging down (rad)."""
        return float(self.data.qpos[self._hinge])

    @property
    def omega(self) -> float:
        """The rod's angular velocity (rad/s)."""
        return float(self.data.qvel[self._dof])

    @property
    def time(self) -> float:
        """The model's simulated time (s)."""
        return float(self.data.time)

    @property
    def driven(self) -> bool:
        """Whether the rod follows the gripper (the grasp's constraint is active) rather than swinging
        freely."""
        return bool(self.data.eq_active[self._eq])

    def set_driven(self, driven: bool) -> None:
        """Switch between free swinging and following the gripper; the state is untouched."""
        self.data.eq_active[self._eq] = 1 if driven else 0

    def set_gripper(self, position) -> None:
        """Place the gripper the driven rod follows; a position that is no gripper's is bounded.

        A non-finite one is ignored (the gripper stays). One farther from the pivot than twice
        the rod's length is brought back to that distance along its direction: the rod still
        turns towards it, where the equality's force from a gripper metres away spun the rod
        (1 km) or overflowed until MuJoCo reset it.
        """
        pos = np.asarray(position, dtype=float)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            return
        pivot = np.asarray(self.p.pivot)
        d = pos - pivot
        big = float(np.max(np.abs(d)))
        u = d / big if big > 0 else d  # scaled, so that its norm cannot overflow
        reach = 2 * self.p.length
        if big * float(np.linalg.norm(u)) > reach:
            pos = pivot + u * (reach / float(np.linalg.norm(u)))
        self.data.mocap_pos[0] = pos

    def angle_at(self, t: float) -> float:
        """The twin's angle at a recent time t (linear between macro-step points)."""
        hist = self._history
        if t >= hist[-1][0]:
            return hist[-1][1]
        for (t0, a0), (t1, a1) in zip(reversed(list(hist)[:-1]), reversed(hist)):
            if t0 <= t <= t1:
                return a0 + (a1 - a0) * (t - t0) / (t1 - t0) if t1 > t0 else a1
        return hist[0][1]

    def correct(self, measured_angle: float, h: float, measured_at: float | None = None) -> None:
        """Observer correction towards a measured angle.

        Without a capture time the measurement is taken as of now and applied over h; with
        one, each new measurement is compared with the twin at its capture time and applied
        over the time since the previous measurement.
        """
        l = self.p.observer_gain
        if l <= 0 or not math.isfinite(measured_angle) or (measured_at is not None and not math.isfinite(measured_at)):
            return  # a NaN or infinite measurement (any node's output may be one) would make the twin NaN
        if measured_at is None:
            self._nudge(_wrapped(measured_angle - self.angle), h)
            return
        newest = self._pending[-1][0] if self._pending else self._last_measurement
        if measured_at > newest:
            self._pending.append((measured_at, measured_angle))
        elif measured_at > self._last_measurement and measured_at != newest:
            # Frames come in the order they were captured, so one captured before a frame that
            # waits means the waiting frames' times were wrong (a bad frame, or a camera whose
            # clock went back): trust the newest arrival. Kept, one frame stamped far in the
            # future would hold back every later frame for the rest of the run.
            self._pending.clear()
            self._pending.append((measured_at, measured_angle))
        # A measurement captured at a time the twin has not reached (the co-simulation fell
        # behind the wall clock the camera lives on) waits until the twin gets there: compared
        # with the twin's present it would drag the twin to the future. It must not wait on the
        # input, which a newer frame replaces: when the run lags the camera by more than a frame
        # every frame is ahead of the twin while it is routed, and none would ever be used.
        while self._pending and self._pending[0][0] <= self.time + 1e-9:
            at, angle = self._pending.popleft()
            # The discrete update is stable while 2·l·dt < 1: after a gap (or at the first
            # measurement) apply at most a quarter of the error's remaining time constant.
            dt = min(at - self._last_measurement, 0.25 / l)
            self._last_measurement = at
            moved = self._nudge(_wrapped(angle - self.angle_at(at)), dt)
            # The twin's past since the capture is what this correction amends. A frame captured
            # meanwhile and still in flight must be compared with it amended, or the same error
            # is corrected once per such frame: with 100 ms of frames in flight on a loaded
            # machine (six of them at 60 frames/s) the twin swung away from the rod, 11-87° in
            # three runs of four.
            for i in range(len(self._history) - 1, -1, -1):
                t, a = self._history[i]
                if t < at:
                    break
                self._history[i] = (t, a + moved)

    def _nudge(self, e: float, dt: float) -> float:
        """Move the twin towards an error ``e`` over ``dt``; the angle it moved."""
        l = self.p.observer_gain
        moved = 2 * l * e * dt
        self.data.qpos[self._hinge] += moved
        self.data.qvel[self._dof] += l * l * e * dt
        return moved

    def snapshot(self) -> dict:
        """Everything a step reads, as plain lists and floats (JSON and msgpack alike): MuJoCo's
        integration state (mj_getState) and the observer's history of the twin's angles."""
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        state = np.empty(mujoco.mj_stateSize(self.model, spec))
        mujoco.mj_getState(self.model, self.data, state, spec)
        return {"mujoco": state.tolist(), "history": [v for pair in self._history for v in pair],
                "last_measurement": self._last_measurement,
                "pending": [v for pair in self._pending for v in pair]}

    def restore(self, snap: dict) -> None:
        """Set the state :meth:`snapshot` gave; ValueError if it is not one of this rod's."""
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        state = np.asarray(snap["mujoco"], dtype=float)
        history = [float(v) for v in snap["history"]]
        last = float(snap["last_measurement"])
        pending = [float(v) for v in snap.get("pending", [])]  # none in a state saved before it was kept
        times = [last, *pending[0::2]]
        # A NaN time would never be reached and hold every later frame back; a time out of order
        # would be applied over a negative interval, pushing the twin away from the rod.
        # MuJoCo resets a state past mjMAXVAL (time too) at the next step, as it does a NaN one.
        if (state.shape != (mujoco.mj_stateSize(self.model, spec),) or not np.all(np.abs(state) <= mujoco.mjMAXVAL)
                or not history or len(history) % 2
                or len(pending) % 2 or math.isnan(last) or not all(map(math.isfinite, pending))
                or any(b <= a for a, b in zip(times, times[1:]))):
            raise ValueError("not a state of this rod model")
        mujoco.mj_setState(self.model, self.data, state, spec)
        mujoco.mj_kinematics(self.model, self.data)
        self._history.clear()
        self._history.extend(zip(history[0::2], history[1::2]))
        self._last_measurement = last
        self._pending.clear()
        self._pending.extend(zip(pending[0::2], pending[1::2]))

    def advance(self, h: float) -> None:
        """Integrate h seconds with MuJoCo's own steps (the macro step's micro-steps)."""
        n = max(1, round(h / self.model.opt.timestep))
        mujoco.mj_step(self.model, self.data, nstep=n)
        mujoco.mj_kinematics(self.model, self.data)
        self._history.append((self.time, self.angle))

    def outputs(self) -> RodOutputs:
        """The rod's state as it stands (:class:`RodOutputs`)."""
        return RodOutputs(self.angle, self.omega, self.data.site_xpos[self._grasp].copy(),
                          self.data.site_xpos[self._tip].copy())

    def energy(self) -> float:
        """Kinetic + potential energy about the pivot (J)."""
        p = self.p
        return 0.5 * p.inertia_about_pivot() * self.omega ** 2 + p.mass * p.gravity * (p.length / 2) * (1 - math.cos(self.angle))

    def point(self, s: float, angle: float | None = None) -> np.ndarray:
        """World position of the point s metres down the rod, at the given (or current) angle."""
        a = self.angle if angle is None else angle
        return np.asarray(self.p.pivot) + s * np.array([0.0, math.sin(a), -math.cos(a)])


def _wrapped(e: float) -> float:
    """An angle error in [-π, π]: the rod at φ + 2π is the rod at φ, and a huge measured angle
    (any finite value a node may send) must not kick the twin until MuJoCo resets it."""
    return math.remainder(e, 2 * math.pi)


def pendulum_period(p: RodParams, amplitude: float) -> float:
    """Undamped period of the rod as a physical pendulum, exact for any amplitude.

    T = 2π·sqrt(I / (m·g·d)) / AGM(1, cos(θ0/2)), the arithmetic–geometric mean form of
    the complete elliptic integral (the large-angle correction).
    """
    t0 = 2 * math.pi * math.sqrt(p.inertia_about_pivot() / (p.mass * p.gravity * p.length / 2))
    a, b = 1.0, math.cos(amplitude / 2)
    while abs(a - b) > 1e-15:
        a, b = (a + b) / 2, math.sqrt(a * b)
    return t0 / a
