"""The KR6 R700 scene: kinematics against hand-computed poses, limits, collisions, grasping, IK, reach."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from hycosim.node.interface import NodeContext, NodeModelError
from hycosim.scenario.robot import kr6
from hycosim.scenario.robot.controller import ReferenceController
from hycosim.scenario.robot.node import initial_pose
from hycosim.scenario.robot.reach import analyse_reach
from hycosim.scenario.robot.scene import RobotScene, SceneParams, grasp_rotation


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


_any = st.floats(allow_nan=True, allow_infinity=True)


@given(steps=st.lists(st.tuples(st.lists(_any, min_size=6, max_size=6), st.booleans(), _any), min_size=1, max_size=6))
@example(steps=[([math.nan] * 6, False, math.nan)])  # a NaN command stayed in the pose for good
def test_any_commands_and_rod_angles_leave_a_finite_pose_that_good_commands_still_move(steps):
    """The scene's inputs come from other nodes: a command or rod angle that is NaN, infinite or
    huge holds that axis (or the rod) where it was; the pose stays finite and within limits, and
    the robot still goes where a good command sends it."""
    scene = RobotScene(SceneParams(check_reach=False))
    for q_cmd, close, rod_angle in steps:
        o = scene.step(0.01, np.array(q_cmd), close, rod_angle)
        assert np.all(np.isfinite(scene.q)) and math.isfinite(scene.rod_angle) and math.isfinite(o.distance)
        assert np.all(scene.q >= kr6.LIMITS[:, 0]) and np.all(scene.q <= kr6.LIMITS[:, 1])
    for _ in range(400):
        scene.step(0.01, kr6.READY, False, 0.3)
    assert np.allclose(scene.q, kr6.READY) and scene.rod_angle == 0.3


@given(q=st.lists(_any, min_size=6, max_size=6), gap=_any, rod_angle=_any, which=st.integers(0, 2))
def test_a_saved_scene_state_restores_only_a_finite_pose_within_limits(q, gap, rod_angle, which):
    scene = RobotScene(SceneParams(check_reach=False))
    snap = scene.snapshot()
    # One part changed at a time, so that a good value in the others is not masked.
    snap.update([{"q": q}, {"gap": gap}, {"rod_angle": rod_angle}][which])
    try:
        scene.restore(snap)
    except ValueError:
        return
    assert np.all(scene.q >= kr6.LIMITS[:, 0]) and np.all(scene.q <= kr6.LIMITS[:, 1])
    assert 0.0 <= scene.gap <= kr6.GRIPPER_OPEN and math.isfinite(scene.rod_angle)
    assert math.isfinite(scene.step(0.01, kr6.READY, False, 0.0).distance)


@given(angle=_any, omega=_any, q=st.lists(_any, min_size=6, max_size=6))
@example(angle=1e300, omega=0.0, q=list(kr6.READY))  # MuJoCo reset the planning rod, which then hung still
@example(angle=0.7, omega=math.nan, q=list(kr6.READY))
def test_the_reference_controller_given_any_inputs_plans_only_from_a_swing(tmp_path_factory, angle, omega, q):
    """Its inputs are other nodes' outputs: the planning rod is never given a state MuJoCo
    resets, the commands stay finite and within limits, and a good swing afterwards is planned."""
    node = ReferenceController()
    node.setup(NodeContext("controller", 3, [], [], {}, 0.01, 0.0, tmp_path_factory.mktemp("ctrl")))
    inputs = {**{f"q{i + 1}": v for i, v in enumerate(q)}, "rod_angle": angle, "rod_omega": omega, "grasped": 0.0}
    node.step(0.0, 0.01, inputs)
    warned = node.rod.data.warning  # the next plan resets the rod, and these with it
    assert not warned[mujoco.mjtWarning.mjWARN_BADQPOS].number + warned[mujoco.mjtWarning.mjWARN_BADQVEL].number
    node.step(0.2, 0.01, {**{f"q{i + 1}": float(v) for i, v in enumerate(kr6.READY)},
                          "rod_angle": math.radians(40), "rod_omega": 0.0, "grasped": 0.0})
    q_cmd = np.array([node.outputs()[f"q_cmd{i + 1}"] for i in range(6)])
    assert np.all(np.isfinite(q_cmd)) and np.all(q_cmd >= kr6.LIMITS[:, 0]) and np.all(q_cmd <= kr6.LIMITS[:, 1])
    assert node.plan is not None and node.plan.t_turn > 0.2


@given(q0=st.lists(_any, min_size=6, max_size=6) | st.lists(st.floats(-400, 400), max_size=8) | st.text(max_size=3)
       | st.none() | st.lists(st.text(max_size=2), min_size=6, max_size=6))
@example(q0=[0, -90, 90, 0, 0, 0])
@example(q0=[171, -90, 90, 0, 0, 0])
def test_a_robot_nodes_initial_pose_is_six_angles_within_limits_or_an_error_naming_it(q0):
    try:
        q = initial_pose("arm", q0)
    except NodeModelError as exc:
        assert "'arm'" in str(exc) and "q0_deg" in str(exc)
        return
    assert np.all(q >= kr6.LIMITS[:, 0]) and np.all(q <= kr6.LIMITS[:, 1])
    assert np.allclose(np.degrees(q), np.asarray(q0, dtype=float))
    scene = RobotScene(SceneParams(check_reach=False))
    scene.set_state(q, kr6.GRIPPER_OPEN, 0.0)
    scene.restore(scene.snapshot())  # a checkpoint of the start restores
