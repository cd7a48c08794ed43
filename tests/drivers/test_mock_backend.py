"""The mock backend: capabilities, scripting from Python and from a config section."""

from __future__ import annotations

import math

import pytest

from mmexec.config.yamlload import InputError, load_yaml_text
from mmexec.drivers.interfaces import GoalState, GraspState, JointTrajectory
from mmexec.drivers.mock import MockRobot, build, parse_section


def spin_until_done(robot: MockRobot, goal, period: float = 0.05, limit: int = 2000) -> int:
    n = 0
    while not goal.done():
        robot.spin(period)
        n += 1
        assert n < limit, "goal never finished"
    return n


def test_spin_advances_clock_and_rejects_bad_period() -> None:
    robot = MockRobot()
    robot.spin(0.05)
    robot.spin(0.05)
    assert robot.clock.now() == pytest.approx(0.1)
    with pytest.raises(ValueError):
        robot.spin(0.0)


def test_arm_follows_trajectory_over_clock_time() -> None:
    robot = MockRobot()
    arm = robot.arm
    traj = JointTrajectory(arm.joint_names, (1.0, 2.0), ((0.5, 0, 0, 0, 0, 0), (1.0, 0, 0, 0, 0, 0)))
    goal = arm.follow(traj)
    for _ in range(10):
        robot.spin(0.05)
    assert arm.state().positions[0] == pytest.approx(0.25)
    assert goal.state is GoalState.ACTIVE
    spin_until_done(robot, goal)
    assert goal.state is GoalState.SUCCEEDED
    assert arm.state().positions[0] == pytest.approx(1.0)
    assert robot.clock.now() == pytest.approx(2.0)


def test_arm_rejects_limits_naming_the_joint() -> None:
    robot = MockRobot()
    arm = robot.arm
    too_far = arm.follow(JointTrajectory(arm.joint_names, (5.0,), ((0, 2.5, 0, 0, 0, 0),)))
    assert too_far.state is GoalState.FAILED and "shoulder" in too_far.reason
    too_fast = arm.follow(JointTrajectory(arm.joint_names, (0.1,), ((1.0, 0, 0, 0, 0, 0),)))
    assert too_fast.state is GoalState.FAILED and "waist" in too_fast.reason and "rad/s" in too_fast.reason
    assert arm.state().positions == (0.0,) * 6


def test_first_two_arm_moves_fail_from_python() -> None:
    robot = MockRobot()
    robot.arm.fail_moves = {1, 2}
    outcomes = []
    for _ in range(3):
        goal = robot.arm.move_to([0.4, 0, 0, 0, 0, 0])
        spin_until_done(robot, goal)
        outcomes.append((goal.state, goal.reason))
    assert [s for s, _ in outcomes] == [GoalState.FAILED, GoalState.FAILED, GoalState.SUCCEEDED]
    assert "scripted, move 1" in outcomes[0][1] and "scripted, move 2" in outcomes[1][1]


def test_arm_cancel_takes_stop_time() -> None:
    robot = MockRobot()
    robot.arm.stop_time = 0.3
    goal = robot.arm.move_to([1.0, 0, 0, 0, 0, 0], speed_scale=0.1)
    robot.spin(0.1)
    goal.cancel()
    assert goal.state is GoalState.CANCELLING
    q_at_cancel = robot.arm.state().positions
    ticks = spin_until_done(robot, goal, period=0.1)
    assert goal.state is GoalState.CANCELLED
    assert ticks == 3
    assert robot.arm.state().positions == q_at_cancel
    assert robot.arm.cancels == 1


def test_base_integrates_with_limits_and_command_timeout() -> None:
    robot = MockRobot()
    base = robot.base
    for _ in range(40):  # 2 s, re-commanding each tick
        base.set_velocity(5.0, 0.0)  # clamped to max_linear
        robot.spin(0.05)
    st = base.state()
    assert st.v == pytest.approx(base.max_linear)
    assert 0.9 < st.pose.x < 1.4  # accelerated at 1 m/s^2 to 0.7 m/s
    for _ in range(40):  # no new command: the watchdog stops it after 0.6 s
        robot.spin(0.05)
    assert base.state().v == 0.0


def test_blocked_base_does_not_move_and_reports_fault() -> None:
    robot = MockRobot()
    robot.base.blocked = True
    for _ in range(10):
        robot.base.set_velocity(0.3, 0.0)
        robot.spin(0.05)
    st = robot.base.state()
    assert st.pose.x == 0.0 and "bumper_centre" in st.faults


def test_gripper_scripted_grasps() -> None:
    robot = MockRobot()
    robot.gripper.grasps = [False, True]
    robot.gripper.default_grasp = False
    results = []
    for _ in range(3):
        spin_until_done(robot, robot.gripper.open())
        goal = robot.gripper.close()
        spin_until_done(robot, goal)
        results.append(goal.result.grasp)
    assert results == [GraspState.AT_POSITION, GraspState.CONTACT_CLOSING, GraspState.AT_POSITION]
    assert robot.gripper.closes == 3


def test_camera_dropouts_and_frame_content() -> None:
    robot = MockRobot()
    robot.camera.dropouts = {2}
    f1, f2, f3 = robot.camera.frame(), robot.camera.frame(), robot.camera.frame()
    assert f2 is None and f1 is not None and f3 is not None
    assert f1.rgb.shape == (48, 64, 3) and f1.depth is not None and float(f1.depth[0, 0]) == pytest.approx(1.0)
    # optical z axis points along base +x
    assert robot.camera.pose_in_base()[:3, 2] == pytest.approx([1.0, 0.0, 0.0])


def test_lidar_scan() -> None:
    robot = MockRobot()
    scan = robot.lidar.scan()
    assert len(scan.ranges) == 360 and float(scan.ranges[0]) == pytest.approx(3.0)
    assert scan.angles[-1] == pytest.approx(math.pi - 2 * math.pi / 360)


CONFIG = """\
capabilities: [base, arm, gripper]
arm:
  fail_moves: [1, 2]
  fail_reason: "no IK"
gripper:
  grasps: [false]
base:
  start: [1.0, 2.0, 0.5]
"""


def test_build_from_section_scripts_outcomes() -> None:
    section = load_yaml_text(CONFIG, "cfg.yaml")
    robot = build(section, profile={"home": [0, 0, 0]}, seed=3, options={"gui": False, "record": None})
    assert robot.camera is None and robot.lidar is None
    assert robot.profile == {"home": [0, 0, 0]}
    assert robot.base.state().pose.x == 1.0
    g = robot.arm.move_to([0.2, 0, 0, 0, 0, 0])
    spin_until_done(robot, g)
    assert g.state is GoalState.FAILED and "no IK" in g.reason


def test_section_errors_have_positions() -> None:
    text = "arm:\n  fail_movs: [1]\ncamera:\n  width: wide\ncapabilities: [base, legs]\n"
    section = load_yaml_text(text, "cfg.yaml")
    with pytest.raises(InputError) as ei:
        parse_section(section)
    msg = str(ei.value)
    assert "cfg.yaml:2:3: mock.arm.fail_movs: unknown key; did you mean 'fail_moves'?" in msg
    assert "cfg.yaml:4:10: mock.camera.width: expected an integer" in msg
    assert "cfg.yaml:5:22: mock.capabilities[1]: expected one of" in msg and "legs" in msg
    assert len(msg.splitlines()) == 3


def test_none_section_gives_defaults() -> None:
    robot = build(None, profile={}, seed=None, options={})
    assert robot.arm is not None and robot.camera is not None
