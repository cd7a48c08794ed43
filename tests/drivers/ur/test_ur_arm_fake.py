"""URArm against the Python-level ur_rtde fakes: motion over clock time, cancel, faults,
limits, deadlines, reconnect, close. Every wait is bounded; no thread outlives a test."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
from urtest_helpers import run_for, step_until, sync, wait_for

from mmexec.drivers.interfaces import GoalState, JointTrajectory, ManualClock
from mmexec.drivers.ur import model as urmodel
from mmexec.drivers.ur.arm import URArm, URArmConfig, URConnectionError
from mmexec.drivers.ur.fake import FakeURController

HOME = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)


def _q(j0: float) -> tuple[float, ...]:
    return (j0,) + HOME[1:]


@pytest.fixture
def rig() -> Iterator[tuple[URArm, FakeURController, ManualClock]]:
    baseline = threading.active_count()
    clock = ManualClock()
    ctrl = FakeURController(clock)
    arm = URArm(
        URArmConfig(host="fake-ur", frequency=200.0, command_timeout=0.3, connect_timeout=2.0),
        clock=clock,
        control_factory=ctrl.control_factory,
        receive_factory=ctrl.receive_factory,
    )
    arm.open()
    yield arm, ctrl, clock
    ctrl.release_blocked_calls()
    arm.close()
    assert wait_for(lambda: threading.active_count() == baseline), "worker thread leaked"


def test_move_to_takes_clock_time_and_arrives(rig: tuple[URArm, FakeURController, ManualClock]) -> None:
    arm, _ctrl, clock = rig
    goal = arm.move_to(_q(0.5), speed_scale=1.0)
    sync(arm, clock)  # the worker has sent moveJ at t = 0
    run_for(arm, clock, 0.2)
    assert goal.state is GoalState.ACTIVE
    assert 0.0 < arm.state().positions[0] < 0.5
    took = step_until(arm, clock, goal)
    assert goal.state is GoalState.SUCCEEDED
    # triangle profile at 1.4 rad/s^2 over 0.5 rad: 2 * sqrt(0.5 / 1.4) = 1.195 s
    assert 1.19 <= took + 0.2 <= 1.4
    assert arm.state().positions[0] == pytest.approx(0.5, abs=1e-3)


def test_follow_streams_servoj_along_the_trajectory(rig: tuple[URArm, FakeURController, ManualClock]) -> None:
    arm, _ctrl, clock = rig
    traj = JointTrajectory(arm.joint_names, (1.0, 2.0), (_q(0.3), _q(-0.3)))
    goal = arm.follow(traj)
    seen = []
    while not goal.done():
        clock.advance(0.05)
        sync(arm, clock)
        sync(arm, clock)
        seen.append((clock.now(), arm.state().positions[0]))
        assert clock.now() < 5.0
    assert goal.state is GoalState.SUCCEEDED
    at_1s = min(seen, key=lambda s: abs(s[0] - 1.0))[1]
    assert at_1s == pytest.approx(0.3, abs=0.05)
    assert max(p for _, p in seen) < 0.3 + 0.05  # followed the path, no overshoot
    assert arm.state().positions[0] == pytest.approx(-0.3, abs=0.01)


def test_cancel_decelerates_then_cancelled(rig: tuple[URArm, FakeURController, ManualClock]) -> None:
    arm, _ctrl, clock = rig
    goal = arm.move_to(_q(1.5), speed_scale=1.0)
    for _ in range(20):
        clock.advance(0.02)
        sync(arm, clock)
    v = arm.state().velocities[0]
    assert v > 0.3
    goal.cancel()
    assert goal.state is GoalState.CANCELLING
    took = step_until(arm, clock, goal)
    assert goal.state is GoalState.CANCELLED
    assert took == pytest.approx(v / arm.config.stop_deceleration, abs=0.08)
    state = arm.state()
    assert max(abs(x) for x in state.velocities) < arm.config.rest_speed
    assert 0.1 < state.positions[0] < 1.0  # stopped on the way, not at the target
    # the arm holds: more clock time does not move it
    run_for(arm, clock, 1.0)
    assert arm.state().positions[0] == pytest.approx(state.positions[0], abs=1e-9)


@pytest.mark.parametrize(
    ("inject", "reason"),
    [
        (FakeURController.protective_stop, "protective stop"),
        (FakeURController.emergency_stop, "emergency stop"),
        (FakeURController.stop_program, "program stopped (runtime state 1: stopped)"),
        (FakeURController.drop_connections, "connection lost: RTDE link to fake-ur closed"),
        (lambda c: c.freeze(True), "connection lost: no new RTDE data from fake-ur"),
        (FakeURController.power_off, "robot not running (robot mode 3: power off)"),
        (lambda c: c.set_state(safety_mode=5), "safeguard stop (safeguard stop)"),
        (lambda c: c.set_state(safety_mode=9), "safety fault (safety mode 9: fault)"),
    ],
    ids=["protective", "estop", "program", "disconnect", "stale", "power_off", "safeguard", "fault"],
)
def test_fault_mid_motion_fails_goal_with_reason(
    rig: tuple[URArm, FakeURController, ManualClock], inject, reason: str  # type: ignore[no-untyped-def]
) -> None:
    arm, ctrl, clock = rig
    goal = arm.follow(JointTrajectory(arm.joint_names, (2.0,), (_q(1.0),)))
    for _ in range(5):
        clock.advance(0.05)
        sync(arm, clock)
    assert goal.state is GoalState.ACTIVE
    inject(ctrl)
    took = step_until(arm, clock, goal, dt=0.02, limit=0.5)
    assert goal.state is GoalState.FAILED
    assert goal.reason.startswith(reason)
    assert took <= arm.config.stale_timeout + 0.1
    # a new goal is refused with the same reason while the fault lasts
    again = arm.move_to(HOME)
    assert again.state is GoalState.FAILED and reason.split(":")[0] in again.reason


def test_limits_rejected_before_anything_is_sent(rig: tuple[URArm, FakeURController, ManualClock]) -> None:
    arm, ctrl, clock = rig
    elbow_out = HOME[:2] + (3.5,) + HOME[3:]
    g = arm.follow(JointTrajectory(arm.joint_names, (10.0,), (elbow_out,)))
    assert g.state is GoalState.FAILED and g.reason.startswith("elbow_joint: waypoint 1 at 3.5000 rad outside")
    too_fast = JointTrajectory(arm.joint_names, (0.5,), (_q(2.0),))  # 4 rad/s > pi
    g = arm.follow(too_fast)
    assert g.state is GoalState.FAILED and "shoulder_pan_joint: segment 0 needs 4.000 rad/s" in g.reason
    g = arm.move_to(HOME[:5] + (7.0,))
    assert g.state is GoalState.FAILED and g.reason.startswith("wrist_3_joint")
    g = arm.follow(JointTrajectory(("a", "b", "c", "d", "e", "f"), (1.0,), (HOME,)))
    assert g.state is GoalState.FAILED and "differ" in g.reason
    run_for(arm, clock, 0.5)
    assert arm.state().positions == pytest.approx(HOME)  # nothing moved
    assert ctrl._mode == "idle"


def test_acceleration_limit_from_config() -> None:
    clock = ManualClock()
    ctrl = FakeURController(clock)
    arm = URArm(URArmConfig(host="fake", acceleration_limit=1.0), clock=clock,
                control_factory=ctrl.control_factory, receive_factory=ctrl.receive_factory)
    try:
        arm.open()
        # 0 -> 1 rad/s in the first 0.5 s segment, then back: |dv|/dt = 2 rad/s^2 > 1
        g = arm.follow(JointTrajectory(arm.joint_names, (0.5, 1.0), (_q(0.5), _q(0.5))))
        assert g.state is GoalState.FAILED and "rad/s^2" in g.reason
    finally:
        arm.close()


def test_busy_and_not_connected_are_refused(rig: tuple[URArm, FakeURController, ManualClock]) -> None:
    arm, ctrl, clock = rig
    first = arm.move_to(_q(0.4))
    second = arm.move_to(_q(0.2))
    assert second.state is GoalState.FAILED and "busy with move_to" in second.reason
    first.cancel()
    step_until(arm, clock, first)
    fresh = URArm(URArmConfig(host="x"), clock=clock, control_factory=ctrl.control_factory,
                  receive_factory=ctrl.receive_factory)
    g = fresh.move_to(HOME)
    assert g.state is GoalState.FAILED and "call connect()" in g.reason
    fresh.close()


def test_reconnect_after_connection_loss(rig: tuple[URArm, FakeURController, ManualClock]) -> None:
    arm, ctrl, clock = rig
    goal = arm.move_to(_q(1.0))
    run_for(arm, clock, 0.1)
    ctrl.drop_connections()
    step_until(arm, clock, goal, limit=0.5)
    assert goal.reason.startswith("connection lost")
    assert not arm.connected
    ctrl.refuse_connections(True)
    r = arm.reconnect()
    assert wait_for(r.done)
    assert r.state is GoalState.FAILED and "Could not connect to: fake-ur at 30004" in r.reason
    ctrl.refuse_connections(False)
    r = arm.reconnect()
    assert wait_for(r.done) and r.state is GoalState.SUCCEEDED
    g = arm.move_to(_q(0.2), speed_scale=1.0)
    step_until(arm, clock, g)
    assert g.state is GoalState.SUCCEEDED


def test_close_leaves_arm_stopped_and_disconnected() -> None:
    baseline = threading.active_count()
    clock = ManualClock()
    ctrl = FakeURController(clock)
    arm = URArm(URArmConfig(host="fake", frequency=200.0), clock=clock,
                control_factory=ctrl.control_factory, receive_factory=ctrl.receive_factory)
    arm.open()
    goal = arm.move_to(_q(1.5), speed_scale=1.0)
    for _ in range(20):
        clock.advance(0.02)
        sync(arm, clock)
    arm.close()
    assert goal.state is GoalState.FAILED and goal.reason == "arm driver closed"
    assert ctrl._mode == "stop"  # decelerating under stopJ, not driving on to the target
    clock.advance(2.0)
    with ctrl._lock:
        ctrl._advance()
        assert not np.any(ctrl._qd)
        assert ctrl._q[0] < 1.0
    assert ctrl.connections == 2 and ctrl.disconnects == 2
    assert threading.active_count() == baseline
    assert arm.move_to(HOME).state is GoalState.FAILED


def test_refused_connection_is_one_line() -> None:
    clock = ManualClock()
    ctrl = FakeURController(clock)
    ctrl.refuse_connections(True)
    arm = URArm(URArmConfig(host="10.0.0.9"), clock=clock, control_factory=ctrl.control_factory,
                receive_factory=ctrl.receive_factory)
    with pytest.raises(URConnectionError) as e:
        arm.open()
    arm.close()
    msg = str(e.value)
    assert "\n" not in msg
    assert msg == "UR 10.0.0.9:30004: cannot connect: Error: Could not connect to: 10.0.0.9 at 30004, verify the IP"


def test_connect_deadline_and_late_interface_is_disconnected() -> None:
    baseline = threading.active_count()
    clock = ManualClock()
    ctrl = FakeURController(clock, connect_delay=60.0)  # released below
    arm = URArm(URArmConfig(host="slow", connect_timeout=0.2), clock=clock,
                control_factory=ctrl.control_factory, receive_factory=ctrl.receive_factory)
    t0 = time.monotonic()
    with pytest.raises(URConnectionError, match="no answer within 0.2 s|did not return within 0.20 s"):
        arm.open()
    assert time.monotonic() - t0 < 30.0  # the deadline fired (a generous bound: not a timing test)
    ctrl.release_blocked_calls()
    arm.close()
    assert ctrl.connections == ctrl.disconnects  # the late interface was not kept
    assert threading.active_count() == baseline


def test_stalled_command_fails_goal_within_its_deadline(rig: tuple[URArm, FakeURController, ManualClock]) -> None:
    arm, ctrl, _clock = rig
    ctrl.command_delay = 5.0
    goal = arm.follow(JointTrajectory(arm.joint_names, (1.0,), (_q(0.2),)))
    t0 = time.monotonic()
    assert wait_for(goal.done, timeout=1.5)
    assert time.monotonic() - t0 < arm.config.command_timeout + 0.3
    assert goal.reason == "connection lost: ur_rtde servoJ did not return within 0.30 s"
    ctrl.command_delay = 0.0
    ctrl.release_blocked_calls()
    assert wait_for(lambda: ctrl.disconnects == 2)  # link torn down once the call came back
    r = arm.reconnect()
    assert wait_for(r.done) and r.state is GoalState.SUCCEEDED


def test_stop_cancels_running_goal(rig: tuple[URArm, FakeURController, ManualClock]) -> None:
    arm, ctrl, clock = rig
    goal = arm.follow(JointTrajectory(arm.joint_names, (2.0,), (_q(1.0),)))
    for _ in range(10):
        clock.advance(0.05)
        sync(arm, clock)
    arm.stop()
    step_until(arm, clock, goal)
    assert goal.state is GoalState.CANCELLED
    assert ctrl._mode == "idle"


def test_tcp_pose_in_ros_base_link(rig: tuple[URArm, FakeURController, ManualClock]) -> None:
    arm, _ctrl, clock = rig
    T = urmodel.forward_kinematics((0.0,) * 6)
    assert T[:3, 3] == pytest.approx([-0.8172, -0.2329, 0.0628], abs=1e-9)  # controller base
    g = arm.move_to((0.0,) * 6, speed_scale=1.0)
    step_until(arm, clock, g)
    T_bl = arm.tcp_pose()
    assert T_bl[:3, 3] == pytest.approx([0.8172, 0.2329, 0.0628], abs=1e-3)  # docs/robots.md 2.1
    # tool0 z axis along +y of base_link at the zero pose (docs/robots.md 2.3)
    assert T_bl[:3, 2] == pytest.approx([0.0, 1.0, 0.0], abs=1e-3)


def test_fake_states_follow_the_vendor_numbers() -> None:
    ctrl = FakeURController(ManualClock())
    r = ctrl.receive_factory("fake")
    ctrl.power_off()
    assert (r.getRobotMode(), r.getRobotStatus() & 1) == (3, 0)  # power-on bit cleared
    ctrl.set_state(robot_mode=7, safety_mode=6)
    assert (r.getSafetyMode(), r.getSafetyStatusBits()) == (6, (1 << 5) | (1 << 7))
    assert r.isEmergencyStopped() and not r.isProtectiveStopped()
    ctrl.set_state(safety_mode=1, runtime_state=1)
    assert (r.getSafetyStatusBits(), r.getRobotStatus()) == (1, 0b01)  # powered, no program
    for bad in ({"robot_mode": 9}, {"safety_mode": 0}, {"runtime_state": 6}):
        with pytest.raises(ValueError, match="unknown"):
            ctrl.set_state(**bad)
    assert (r.getRobotMode(), r.getSafetyMode(), r.getRuntimeState()) == (7, 1, 1)  # unchanged


def test_fake_rtde_watchdog_and_ik() -> None:
    clock = ManualClock()
    ctrl = FakeURController(clock)
    ctl = ctrl.control_factory("h")
    rcv = ctrl.receive_factory("h")
    assert ctl.servoJ(list(_q(1.0)), 0, 0, 0.002, 0.1, 300)
    clock.advance(0.05)
    assert rcv.getActualQ()[0] == pytest.approx(0.05 * math.pi)
    clock.advance(0.5)  # no watchdog armed: the script servos on to the last target and holds it
    assert rcv.getActualQ()[0] == pytest.approx(1.0) and rcv.getRuntimeState() == 2
    assert ctl.setWatchdog(10.0)
    assert ctl.servoJ(list(HOME), 0, 0, 0.002, 0.1, 300)  # back towards 0
    clock.advance(0.05)
    assert ctl.kickWatchdog()
    t_kick = clock.now()
    clock.advance(0.08)  # less than 1 / 10 Hz since the kick: running
    assert rcv.getRuntimeState() == 2 and rcv.getActualQd()[0] == pytest.approx(-math.pi)
    clock.advance(0.5)  # silence longer than the watchdog period: the program stops, the arm with it
    (stop,) = ctrl.watchdog_stops
    assert stop.t == pytest.approx(t_kick + 0.1) and stop.last_input == pytest.approx(t_kick)
    assert stop.q[0] == pytest.approx(1.0 - 0.15 * math.pi) and stop.qd[0] == pytest.approx(-math.pi)
    assert rcv.getActualQ()[0] == pytest.approx(stop.q[0]) and rcv.getActualQd() == [0.0] * 6
    assert rcv.getRuntimeState() == 1 and not ctl.servoJ(list(HOME), 0, 0, 0.002, 0.1, 300)
    ctl2 = ctrl.control_factory("h")  # a new control interface starts the script again
    assert rcv.getRuntimeState() == 2 and ctl2.servoJ(list(HOME), 0, 0, 0.002, 0.1, 300)
    clock.advance(1.0)  # the new program has no watchdog until setWatchdog
    assert len(ctrl.watchdog_stops) == 1 and rcv.getActualQ()[0] == pytest.approx(0.0)
    q = [0.3, -1.2, 1.3, -1.5, -1.5, 0.2]
    pose = ctl.getForwardKinematics(q)
    assert ctl.getInverseKinematics(pose, [0.25, -1.15, 1.25, -1.45, -1.45, 0.15]) == pytest.approx(q, abs=1e-3)
    with pytest.raises(RuntimeError):
        ctl.getInverseKinematics([2.0, 0.0, 0.5, 0.0, 3.14, 0.0])  # 2 m away: out of reach
    assert not ctl.getInverseKinematicsHasSolution([2.0, 0.0, 0.5, 0.0, 3.14, 0.0])
    ctrl.protective_stop()
    assert not ctl.moveJ(list(HOME), 1.0, 1.0, True)
    assert rcv.isProtectiveStopped() and not rcv.isEmergencyStopped()
    ctrl.clear_faults()
    ctrl.safety_refuses = True
    assert not ctl.isJointsWithinSafetyLimits(list(HOME))
    assert not ctl.moveJ(list(HOME), 1.0, 1.0, True)
