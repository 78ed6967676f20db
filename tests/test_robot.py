"""The KR6 R700 scene: kinematics against hand-computed poses, limits, collisions, grasping, IK, reach."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clients.robot import kr6
from clients.robot.reach import analyse_reach
from clients.robot.scene import RobotScene, SceneParams, grasp_rotation


def _flange(scene: RobotScene) -> np.ndarray:
    return scene.data.site_xpos[scene.model.site("flange").id]


@pytest.mark.parametrize("q_deg, expected", [
    # all zero: arm stretched along +x: x = 0.025 + 0.315 + 0.365 + 0.080, z = 0.400 + 0.035
    ((0, 0, 0, 0, 0, 0), (0.785, 0.0, 0.435)),
    # HOME: upper arm up (0.315), forearm forward: x = 0.025 + 0.365 + 0.080, z = 0.400 + 0.315 + 0.035
    ((0, -90, 90, 0, 0, 0), (0.470, 0.0, 0.750)),
    # HOME turned by A1 = 90° about −z: the arm points to −y
    ((90, -90, 90, 0, 0, 0), (0.0, -0.470, 0.750)),
    # A5 = 90° at HOME: the flange (0.080) points down
    ((0, -90, 90, 0, 90, 0), (0.390, 0.0, 0.670)),
    # A2 = −90, A3 = 0: everything straight up: z = 0.4 + 0.315 + 0.365 + 0.080, x = 0.025 − 0.035
    ((0, -90, 0, 0, 0, 0), (-0.010, 0.0, 1.160)),
])
def test_forward_kinematics_against_hand_computed_poses(q_deg, expected):
    scene = RobotScene(SceneParams(check_reach=False))
    scene.set_state(np.radians(q_deg), kr6.GRIPPER_OPEN, 0.0)
    assert np.allclose(_flange(scene), expected, atol=1e-9)
    assert np.allclose(kr6.forward_kinematics(np.radians(q_deg))[0], expected, atol=1e-9)


def test_offsets_agree_with_the_datasheet_reach():
    # Datasheet reach: A1 axis to the wrist point, arm stretched. The URDF offsets give 705.9 mm.
    stretched = RobotScene(SceneParams(check_reach=False))
    stretched.set_state(np.zeros(6), kr6.GRIPPER_OPEN, 0.0)
    wrist = stretched.data.xpos[stretched.model.body("link5").id]
    shoulder_to_wrist = math.hypot(wrist[0], wrist[2] - 0.400)
    assert abs(shoulder_to_wrist - kr6.REACH) < 0.002


def test_joint_limits_and_speed_limits_are_enforced():
    scene = RobotScene(SceneParams(check_reach=False))
    h = 0.01
    far = np.radians([400, 400, 400, 400, 400, 400])
    for _ in range(3):
        before = scene.q.copy()
        scene.step(h, far, False, 0.0)
        assert np.all(np.abs(scene.q - before) <= kr6.SPEEDS * h + 1e-12)
        assert np.any(np.abs(scene.q - before) > 0)
    for _ in range(400):
        scene.step(h, far, False, 0.0)
    assert np.allclose(scene.q, kr6.LIMITS[:, 1])
    for _ in range(600):
        scene.step(h, -far, False, 0.0)
    assert np.allclose(scene.q, kr6.LIMITS[:, 0])


def test_known_colliding_poses_are_flagged_and_home_is_clear():
    scene = RobotScene(SceneParams(check_reach=False))
    assert scene.collisions() == []
    scene.set_state(np.radians([0, 40, 30, 0, 0, 0]), kr6.GRIPPER_OPEN, 0.0)  # forearm into the floor
    assert any("floor" in pair for pair in scene.collisions())
    scene.set_state(np.radians([0, -90, 156, 0, 120, 0]), kr6.GRIPPER_OPEN, 0.0)  # folded onto itself
    assert scene.collisions() and all("floor" not in pair and "rod" not in pair for pair in scene.collisions())
    scene.set_state(np.zeros(6), kr6.GRIPPER_OPEN, 0.0)  # stretched through the hanging rod
    assert ("link4", "rod") in scene.collisions() or ("rod", "link4") in scene.collisions()
    assert scene.outputs().collision


def _at_grasp(scene: RobotScene, angle: float) -> None:
    ik = scene.reach(angle)
    assert ik.converged
    scene.set_state(ik.q, kr6.GRIPPER_OPEN, angle)


def test_grasp_detection_closes_on_the_rod_only_when_it_is_between_the_jaws():
    scene = RobotScene(SceneParams(check_reach=False))
    angle = math.radians(-35)
    _at_grasp(scene, angle)
    assert not scene.outputs(True).grasped  # open jaws hold nothing
    for _ in range(10):
        out = scene.step(0.01, scene.q, True, angle)
    assert out.grasped and math.isclose(out.gap, 2 * scene.p.rod_radius)
    assert out.distance < 1e-3 and not out.collision
    assert np.allclose(out.grip_target, scene.data.site_xpos[scene.model.site("rod_grasp").id], atol=1e-3)
    # The same closing with the rod swung 5 cm away: the jaws close on air, a near miss.
    other = RobotScene(SceneParams(check_reach=False))
    _at_grasp(other, angle)
    away = angle + 0.05 / other.p.grasp_distance * 1.0
    for _ in range(10):
        out = other.step(0.01, other.q, True, away)
    assert not out.grasped and out.gap == 0.0
    assert out.near_miss


def test_jaws_closed_on_nothing_cannot_catch_a_rod_swinging_through_them():
    scene = RobotScene(SceneParams(check_reach=False))
    angle = math.radians(-35)
    _at_grasp(scene, angle)
    away = angle + 0.15 / scene.p.grasp_distance
    for _ in range(10):
        out = scene.step(0.01, scene.q, True, away)
    assert out.gap == 0.0 and not out.grasped
    for a in np.linspace(away, angle - 0.1, 40):  # the rod swings through where the jaws met
        out = scene.step(0.01, scene.q, True, a)
        assert not out.grasped and out.gap == 0.0
    for _ in range(10):  # opened, and closed again with the rod between them
        scene.step(0.01, scene.q, False, angle)
    for _ in range(10):
        out = scene.step(0.01, scene.q, True, angle)
    assert out.grasped and math.isclose(out.gap, 2 * scene.p.rod_radius)


def test_ik_reaches_targets_within_limits():
    scene = RobotScene(SceneParams(check_reach=False))
    for deg in (-45, 0, 30):
        r = scene.reach(math.radians(deg))
        assert r.converged and r.position_error < 1e-4
        assert np.all(r.q >= kr6.LIMITS[:, 0]) and np.all(r.q <= kr6.LIMITS[:, 1])
        scene.set_state(r.q, kr6.GRIPPER_OPEN, math.radians(deg))
        assert np.allclose(scene.tcp_rot, grasp_rotation(math.radians(deg)), atol=1e-3)


def test_reach_analysis_finds_the_reachable_part_of_the_swing():
    report = analyse_reach(SceneParams(check_reach=False), max_deg=75, step_deg=5)
    lo, hi = report.reachable_range()
    assert lo <= -60 and hi >= 60
    assert not all(p.reachable for p in report.points)  # the extremes are out of reach
    assert report.fraction_of_swing(60) == 1.0
    far = analyse_reach(SceneParams(pivot=(0.9, 0.0, 1.0), check_reach=False), max_deg=60, step_deg=10)
    assert far.reachable_range() is None or far.fraction_of_swing(60) < 0.5
