"""KUKA KR6 R700 sixx: kinematics, limits and the MuJoCo scene (the paper's Process Simulate cell).

Sources of the numbers:

* Link offsets and axis directions: the ROS-Industrial ``kuka_kr6_support`` URDF of the
  KR6 R700 sixx (shipped on PyPI in ``rtb-data`` as
  ``rtbdata/xacro/kuka_description/kuka_kr6/urdf/kr6r700sixx_macro.xacro``): A1 at z 0.400,
  A2 x 0.025, A3 x 0.315, A4 z 0.035, A5 x 0.365, A6 x 0.080 to the flange; axes −z, +y, +y,
  −x, +y, −x. Stretched, they put the wrist point (A5) 0.025 + hypot(0.680, 0.035) = 0.7059 m
  from A1 at the height of A2, within 1 mm of the datasheet's maximum reach of 706.7 mm.
* Joint limits: KUKA KR AGILUS sixx datasheet (KR 6 R700 sixx): A1 ±170°, A2 −190°…+45°,
  A3 −120°…+156°, A4 ±185°, A5 ±120°, A6 ±350°.
* Axis speeds, same datasheet: 360, 300, 360, 381, 388, 615 °/s.
* HOME = (0, −90, 90, 0, 0, 0)°, the KUKA default: upper arm vertical, forearm horizontal.

Link volumes are capsules sized to the real arm's envelope (no meshes are needed offline);
they are what collision checks use. The gripper is a simple parallel-jaw gripper on the
flange: a 0.06 m body and two 0.06 m fingers; the TCP is mid-jaw, 0.09 m out.
"""

from __future__ import annotations

import math

import numpy as np

AXES = ("a1", "a2", "a3", "a4", "a5", "a6")
OFFSETS = ((0.0, 0.0, 0.400), (0.025, 0.0, 0.0), (0.315, 0.0, 0.0), (0.0, 0.0, 0.035), (0.365, 0.0, 0.0),
           (0.080, 0.0, 0.0))
AXIS_DIRS = ((0, 0, -1), (0, 1, 0), (0, 1, 0), (-1, 0, 0), (0, 1, 0), (-1, 0, 0))
LIMITS_DEG = ((-170, 170), (-190, 45), (-120, 156), (-185, 185), (-120, 120), (-350, 350))
SPEED_DEG = (360, 300, 360, 381, 388, 615)
HOME_DEG = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)
# The cell's ready pose: TCP at (0.45, 0, 0.70) m, jaws level, 17 cm in front of the rod's
# swing plane. From HOME the jaws sit 6 cm from the plane, and the first move of the
# independent axes can sweep the gripper into the passing rod.
READY_DEG = (0.0, -110.8, 115.4, 0.0, -4.6, 0.0)
LIMITS = np.radians(np.array(LIMITS_DEG, dtype=float))
SPEEDS = np.radians(np.array(SPEED_DEG, dtype=float))
HOME = np.radians(np.array(HOME_DEG, dtype=float))
READY = np.radians(np.array(READY_DEG, dtype=float))
REACH = 0.7067  # m, datasheet
TCP_OFFSET = 0.09  # m from the flange along its x axis: mid-jaw
GRIPPER_OPEN = 0.08  # m between the jaws
FINGER_SPEED = 1.0  # m/s, jaws closing


def closing_time(gap: float, rod_radius: float) -> float:
    """Seconds for jaws ``gap`` apart to close onto a rod of ``rod_radius``."""
    return max(0.0, gap - 2 * rod_radius) / FINGER_SPEED


def _rot(axis: tuple[int, int, int], angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float)
    a /= np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def forward_kinematics(q: np.ndarray, base: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Flange position and rotation from joint angles, straight from the offsets above.

    An independent check of the MuJoCo model (which the scene uses): the two must agree.
    """
    pos = np.zeros(3) if base is None else np.asarray(base, dtype=float)
    rot = np.eye(3)
    for offset, axis, angle in zip(OFFSETS, AXIS_DIRS, q):
        pos = pos + rot @ np.asarray(offset)
        rot = rot @ _rot(axis, angle)
    return pos, rot


def _capsule(frm: tuple[float, float, float], to: tuple[float, float, float], r: float, name: str,
             rgba: str = "1 0.5 0 1", group: int = 1) -> str:
    return (f'<geom name="{name}" type="capsule" fromto="{frm[0]} {frm[1]} {frm[2]} {to[0]} {to[1]} {to[2]}" '
            f'size="{r}" rgba="{rgba}" group="{group}"/>')


def scene_mjcf(base: tuple[float, float, float] = (0.0, 0.0, 0.0), rod_length: float = 0.6, rod_radius: float = 0.01,
               pivot: tuple[float, float, float] = (0.62, 0.0, 1.0), grasp_distance: float = 0.4) -> str:
    """The robot cell: floor, KR6 R700 with gripper, and the rod mirrored from the rod node."""
    lo, hi = LIMITS_DEG[0]
    names = AXES
    j = [f'<joint name="{n}" type="hinge" axis="{a[0]} {a[1]} {a[2]}" range="{lim[0]} {lim[1]}"/>'
         for n, a, lim in zip(names, AXIS_DIRS, LIMITS_DEG)]
    px, py, pz = pivot
    return f"""
<mujoco model="kr6r700sixx-cell">
  <compiler angle="degree" autolimits="true"/>
  <option timestep="0.001"/>
  <default>
    <geom contype="1" conaffinity="1" margin="0.0"/>
  </default>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1" rgba="0.8 0.8 0.8 1"/>
    <body name="base" pos="{base[0]} {base[1]} {base[2]}">
      <geom name="base" type="cylinder" fromto="0 0 0.01 0 0 0.19" size="0.09" rgba="0.3 0.3 0.3 1"/>
      <body name="link1" pos="0 0 0.400">
        {j[0]}
        {_capsule((0, 0, -0.17), (0, 0, -0.03), 0.075, "link1")}
        <body name="link2" pos="0.025 0 0">
          {j[1]}
          {_capsule((0.04, 0, 0), (0.275, 0, 0), 0.055, "link2")}
          <body name="link3" pos="0.315 0 0">
            {j[2]}
            {_capsule((0, 0, 0.0), (0, 0, 0.035), 0.05, "link3")}
            <body name="link4" pos="0 0 0.035">
              {j[3]}
              {_capsule((0.08, 0, 0), (0.30, 0, 0), 0.04, "link4")}
              <body name="link5" pos="0.365 0 0">
                {j[4]}
                {_capsule((-0.02, 0, 0), (0.03, 0, 0), 0.035, "link5")}
                <body name="link6" pos="0.080 0 0">
                  {j[5]}
                  <site name="flange" pos="0 0 0" size="0.01"/>
                  {_capsule((0.0, 0, 0), (0.02, 0, 0), 0.03, "gripper_body", "0.2 0.2 0.2 1")}
                  <body name="finger_l" pos="0.06 {GRIPPER_OPEN / 2 + 0.005} 0">
                    <joint name="finger_l" type="slide" axis="0 -1 0" range="0 0.045"/>
                    <geom name="finger_l" type="box" pos="0.03 0.005 0" size="0.03 0.005 0.012" rgba="0.2 0.2 0.2 1"/>
                  </body>
                  <body name="finger_r" pos="0.06 {-GRIPPER_OPEN / 2 - 0.005} 0">
                    <joint name="finger_r" type="slide" axis="0 1 0" range="0 0.045"/>
                    <geom name="finger_r" type="box" pos="0.03 -0.005 0" size="0.03 0.005 0.012" rgba="0.2 0.2 0.2 1"/>
                  </body>
                  <site name="tcp" pos="{TCP_OFFSET} 0 0" size="0.008" rgba="0 1 0 1"/>
                </body>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
    <body name="rod" pos="{px} {py} {pz}">
      <joint name="rod" type="hinge" axis="1 0 0"/>
      <geom name="rod" type="cylinder" fromto="0 0 0 0 0 {-rod_length}" size="{rod_radius}" rgba="0.85 0.1 0.1 1"/>
      <site name="rod_grasp" pos="0 0 {-grasp_distance}" size="0.006"/>
    </body>
  </worldbody>
  <contact>
    <exclude body1="base" body2="link1"/>
    <exclude body1="base" body2="link2"/>
    <exclude body1="link2" body2="link4"/>
    <exclude body1="link3" body2="link5"/>
    <exclude body1="link4" body2="link6"/>
    <exclude body1="link5" body2="finger_l"/>
    <exclude body1="link5" body2="finger_r"/>
    <exclude body1="finger_l" body2="finger_r"/>
  </contact>
</mujoco>
"""
