"""The LoCoBot's pan/tilt head (servos 10, 11) on the fake DYNAMIXEL bus: the goal
positions the servos saw, limits refused before anything is sent, the servos' own position
limits, cancel and close, faults and link loss, the head moving during an arm trajectory,
and a camera riding on the head in a robot built from a config."""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from dxl_helpers import until, wait

from mmexec.drivers import robot as rb
from mmexec.drivers.camera.config import CameraConfig, MountConfig
from mmexec.drivers.camera.uvc import UVCCamera
from mmexec.drivers.descriptions import locobot_wx250s
from mmexec.drivers.descriptions.head import HeadModel
from mmexec.drivers.dynamixel.control_table import pulses_to_rad, rad_to_pulses
from mmexec.drivers.dynamixel.wx250s import WX250s, WX250sConfig
from mmexec.drivers.fakes.dynamixel import FakeDxlBus, wx250s_servos
from mmexec.drivers.interfaces import CameraFrame, GoalState, JointTrajectory

TEST_LATENCY = 0.05  # as in conftest.py
NAMES = ("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate")
PAN, TILT = 10, 11


def cfg(port: str, **kw: object) -> WX250sConfig:
    kw.setdefault("bus_watchdog_ms", 1000)
    return WX250sConfig(port=port, latency=TEST_LATENCY, locobot=True, **kw)  # type: ignore[arg-type]


@pytest.fixture
def fake(no_leaks: None) -> Iterator[FakeDxlBus]:
    dev = FakeDxlBus(wx250s_servos(locobot=True))
    dev.start()
    try:
        yield dev
    finally:
        dev.stop()


@pytest.fixture
def dev(fake: FakeDxlBus) -> Iterator[WX250s]:
    d = WX250s(cfg(fake.port))
    d.connect()
    try:
        yield d
    finally:
        d.close()


def point(dev: WX250s, pan: float, tilt: float, timeout: float = 5.0) -> None:
    goal = dev.head.point(pan, tilt)
    wait(goal, timeout)
    assert goal.state is GoalState.SUCCEEDED, goal.reason


def test_a_bare_arm_has_no_head(no_leaks: None) -> None:
    assert WX250s(WX250sConfig(port="/dev/nope")).head is None


def test_bring_up_limits_the_head_servos_themselves(dev: WX250s, fake: FakeDxlBus) -> None:
    for dxl_id in (PAN, TILT):
        s = fake.servo(dxl_id)
        assert s.torque and s.get("operating_mode") == 3  # position mode
        assert (s.get("min_position_limit"), s.get("max_position_limit")) == (1024, 3072)
    assert fake.servo(TILT).get("drive_mode") & 0x01  # tilt reversed
    head = dev.head
    assert head.joint_names == ("pan", "tilt")
    assert [(lim.lower, lim.upper) for lim in head.limits] == [(-math.pi / 2, math.pi / 2), (-math.pi / 2, 1.309)]
    st = head.state()
    assert (st.pan, st.tilt) == pytest.approx((0.0, 0.0), abs=0.002) and st.fault == ""


def test_point_sends_the_goal_positions_and_succeeds_at_the_target(dev: WX250s, fake: FakeDxlBus) -> None:
    for pan, tilt in ((0.6, 0.35), (-1.2, -0.4), (0.0, 1.2)):
        point(dev, pan, tilt)
        assert fake.servo(PAN).goal_log[-1] == rad_to_pulses(pan)
        assert fake.servo(TILT).goal_log[-1] == rad_to_pulses(tilt)
        st = dev.head.state()
        assert st.pan == pytest.approx(pan, abs=dev.config.tolerance)
        assert st.tilt == pytest.approx(tilt, abs=dev.config.tolerance)
        assert pulses_to_rad(fake.register(PAN, "present_position")) == pytest.approx(pan, abs=0.002)
    # one Goal Position per move reached each servo: written once, not streamed
    assert len(fake.servo(PAN).goal_log) == 1 + 3  # bring-up's goal = present, then the three moves


def test_targets_outside_the_limits_are_refused_and_nothing_is_sent(dev: WX250s, fake: FakeDxlBus) -> None:
    point(dev, 0.3, 0.2)
    before = (list(fake.servo(PAN).goal_log), list(fake.servo(TILT).goal_log))
    for pan, tilt, joint in ((1.7, 0.0, "pan"), (0.0, 1.4, "tilt"), (0.0, -1.6, "tilt"), (math.inf, 0.0, "pan")):
        goal = dev.head.point(pan, tilt)
        assert goal.state is GoalState.FAILED and goal.reason.startswith(f"{joint} = ") and "nothing was sent" in goal.reason
    assert until(lambda: False, 0.2) is False  # a few cycles pass
    assert (fake.servo(PAN).goal_log, fake.servo(TILT).goal_log) == before
    assert dev.head.state().pan == pytest.approx(0.3, abs=0.02)


def test_cancel_holds_where_the_head_is(dev: WX250s, fake: FakeDxlBus) -> None:
    point(dev, -1.5, 0.0)
    goal = dev.head.point(1.5, 0.0)  # 3 rad at pi rad/s: about a second
    assert until(lambda: dev.head.state().pan > -1.0)
    goal.cancel()
    wait(goal, 1.0)
    assert goal.state is GoalState.CANCELLED
    # goal = present, part way (the fake reads the hold from the pty a moment later)
    assert until(lambda: -1.4 < pulses_to_rad(fake.servo(PAN).goal_log[-1]) < 1.4), fake.servo(PAN).goal_log[-3:]
    held = fake.servo(PAN).goal_log[-1]
    assert until(lambda: abs(fake.register(PAN, "present_position") - held) <= 1)


def test_the_head_moves_on_while_an_arm_trajectory_is_cancelled(dev: WX250s, fake: FakeDxlBus) -> None:
    arm = dev.arm.follow(JointTrajectory(NAMES, (2.0,), ((0.5, -0.5, 0.5, 0.0, 0.3, 0.0),)))
    head = dev.head.point(1.0, 0.5)
    assert until(lambda: dev.head.state().pan > 0.1)
    arm.cancel()
    wait(arm, 1.0)
    wait(head, 5.0)
    assert arm.state is GoalState.CANCELLED and head.state is GoalState.SUCCEEDED, head.reason
    assert dev.head.state().pan == pytest.approx(1.0, abs=0.02)


def test_a_hardware_fault_on_the_pan_servo_fails_the_goal(dev: WX250s, fake: FakeDxlBus) -> None:
    goal = dev.head.point(1.2, 0.0)
    assert until(lambda: dev.head.state().pan > 0.1)
    fake.inject_hardware_error(PAN, "overheating")
    wait(goal, 2.0)
    assert goal.state is GoalState.FAILED and "servo id 10 (pan): overheating" in goal.reason
    assert "overheating" in dev.head.state().fault
    refused = dev.head.point(0.0, 0.0)
    assert refused.state is GoalState.FAILED and "servo id 10 (pan)" in refused.reason


def test_a_lost_link_fails_the_goal(dev: WX250s, fake: FakeDxlBus) -> None:
    goal = dev.head.point(-1.2, 0.5)
    assert until(lambda: dev.head.state().pan < -0.1)
    fake.unplug()
    wait(goal, 3.0)
    assert goal.state is GoalState.FAILED and "link lost" in goal.reason
    assert dev.head.point(0.0, 0.0).state is GoalState.FAILED


def test_close_cancels_and_keeps_torque_by_default(fake: FakeDxlBus) -> None:
    d = WX250s(cfg(fake.port))
    d.connect()
    goal = d.head.point(1.0, 0.0)
    d.close()
    assert goal.state is GoalState.CANCELLED
    assert fake.servo(PAN).torque and fake.servo(TILT).torque


def test_close_turns_the_head_torque_off_when_configured(fake: FakeDxlBus) -> None:
    d = WX250s(cfg(fake.port, torque_off_on_close=True))
    d.connect()
    point(d, 0.4, 0.2)
    d.close()
    assert not fake.servo(PAN).torque and not fake.servo(TILT).torque
    assert not fake.servo(1).torque


# --------------------------------------------------------------------------- in a robot


W, H = 64, 48


@pytest.fixture
def video(tmp_path: Path) -> Path:
    path = tmp_path / "head.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (W, H))
    assert writer.isOpened()
    for _ in range(10):
        writer.write(np.full((H, W, 3), (10, 40, 200), dtype=np.uint8))
    writer.release()
    return path


D435_AT_ZERO = "{xyz: [0.101445, 0.017456, 0.561689], rpy: [-1.5707963, 0.0, -1.5707963]}"


def _robot_config(tmp_path: Path, port: str, video: Path, head: str) -> Path:
    p = tmp_path / "run.yaml"
    p.write_text(
        "backend: robot\nrate_hz: 20\nrobot:\n"
        f"  arm: {{kind: wx250s, port: {port}, latency: {TEST_LATENCY}, bus_watchdog_ms: 1000, locobot: true}}\n"
        f"{head}"
        f"  camera: {{kind: uvc, device: {video}, width: {W}, height: {H}, hfov: 1.0, frame_timeout: 60.0,\n"
        f"           mount_link: head, pose_in_base: {D435_AT_ZERO}}}\n")
    return p


def test_a_camera_on_the_head_follows_its_measured_joints(tmp_path: Path, fake: FakeDxlBus, video: Path) -> None:
    from mmexec.executive.config import build_robot, load_config

    loaded = load_config(_robot_config(tmp_path, fake.port, video, "  head: {kind: wx250s_head, home: [0.0, 0.35]}\n"))
    robot = build_robot(loaded, seed=None, options={})
    try:
        assert robot.head is not None and robot.head.home == (0.0, 0.35)
        model = HeadModel.of(locobot_wx250s.DESCRIPTION)
        assert model is not None
        # at pan = tilt = 0 the configured pose is the description's optical frame
        assert robot.camera.pose_in_base() == pytest.approx(model.T_root_optical(0.0, 0.0), abs=1e-5)
        goal = robot.head.point(0.5, 0.4)
        wait(goal, 5.0)
        assert goal.state is GoalState.SUCCEEDED, goal.reason
        st = robot.head.state()
        assert robot.camera.pose_in_base() == pytest.approx(model.T_root_optical(st.pan, st.tilt), abs=1e-5)
        # a frame grabbed now carries that pose (the shipped camera read its short video at
        # bring-up: a second one on the same mount grabs after the move)
        cam = UVCCamera(CameraConfig(device=str(video), width=W, height=H, hfov=1.0, frame_timeout=60.0,
                                     pose_in_base=MountConfig((0.101445, 0.017456, 0.561689),
                                                              (-1.5707963, 0.0, -1.5707963))),
                        clock=robot.clock, link_pose=functools.partial(rb._head_motion, robot, model))
        cam.open()
        robot.add_closer("second camera", cam.close)
        assert until(lambda: cam.frame() is not None, 5.0)
        frame = cam.frame()
        assert isinstance(frame, CameraFrame)
        assert frame.T_base_camera == pytest.approx(model.T_root_optical(st.pan, st.tilt), abs=1e-5)
        robot.safe_stop()
    finally:
        robot.close()


def test_head_config_problems_are_located(tmp_path: Path, video: Path) -> None:
    from mmexec.config.yamlload import InputError
    from mmexec.executive.config import load_config

    bad_home = _robot_config(tmp_path, "/dev/nope", video, "  head: {kind: wx250s_head, home: [0.0, 1.4]}\n")
    with pytest.raises(InputError) as e:
        rb.check(load_config(bad_home).section())
    assert "robot.head.home: tilt = 1.4000 rad outside its limits" in str(e.value)
    no_head = _robot_config(tmp_path, "/dev/nope", video, "")
    with pytest.raises(InputError) as e:
        rb.check(load_config(no_head).section())
    assert "robot.camera.mount_link: 'head' needs 'head: {kind: wx250s_head}'" in str(e.value)


def test_a_camera_pose_without_head_joints_is_a_capability_error(no_leaks: None) -> None:
    from mmexec.drivers.interfaces import CapabilityError

    model = HeadModel.of(locobot_wx250s.DESCRIPTION)
    robot = rb.RealRobot("r", {})
    with pytest.raises(CapabilityError, match="the head carrying the camera is not connected"):
        rb._head_motion(robot, model)
    robot.head = WX250s(cfg("/dev/nope")).head  # never connected: no reading
    with pytest.raises(CapabilityError, match="the head's joints are not known: /dev/nope: no head state yet"):
        rb._head_motion(robot, model)


def test_a_head_that_does_not_get_there_fails_and_holds(dev: WX250s, fake: FakeDxlBus) -> None:
    fake.servo(PAN)._set("profile_velocity", 1)  # the servo crawls (0.229 rev/min): as if held back
    goal = dev.head.point(1.0, 0.0)
    wait(goal, 5.0)
    assert goal.state is GoalState.FAILED
    assert goal.reason.startswith("head joint pan (servo id 10) is ") and "holding" in goal.reason
    # the next cycle writes goal = present, where it had got to
    assert until(lambda: pulses_to_rad(fake.servo(PAN).goal_log[-1]) < 0.5), fake.servo(PAN).goal_log[-3:]
