"""Cameras in the ``robot`` backend: a RealRobot built from a config whose camera is a
video file (UVC through cv2.VideoCapture) and whose base and gripper are the fakes;
frames carry the configured intrinsics and mount; RealSense without pyrealsense2 is a
one-line error before any device is opened; the wrist mount follows the UR arm."""

from __future__ import annotations

import functools
import importlib.util
import math
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from mmexec.config.yamlload import InputError
from mmexec.drivers import robot as rb
from mmexec.drivers.camera.config import CameraConfig, MountConfig
from mmexec.drivers.camera.uvc import UVCCamera
from mmexec.drivers.fakes.kobuki import KobukiFake
from mmexec.drivers.fakes.robotiq import FakeRobotiq
from mmexec.drivers.interfaces import CameraFrame, ManualClock
from mmexec.executive.config import build_robot, load_config

W, H = 64, 48


def _wait(pred: Callable[[], object], timeout: float = 5.0) -> object:
    """Poll ``pred`` until it returns something truthy or ``timeout`` s of real time pass."""
    ev = threading.Event()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        got = pred()
        if got:
            return got
        ev.wait(0.005)
    return pred()


@pytest.fixture
def video(tmp_path: Path) -> Path:
    """Ten 64x48 frames of solid RGB (200, 40, 10), MJPG in an AVI."""
    path = tmp_path / "head.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (W, H))
    assert writer.isOpened()
    for _ in range(10):
        writer.write(np.full((H, W, 3), (10, 40, 200), dtype=np.uint8))  # BGR
    writer.release()
    return path


@pytest.fixture
def fakes() -> Iterator[tuple[KobukiFake, FakeRobotiq]]:
    before = threading.active_count()
    base, grip = KobukiFake(), FakeRobotiq()
    base.start()
    grip.start()
    try:
        yield base, grip
    finally:
        grip.stop()
        base.stop()
    assert _wait(lambda: threading.active_count() <= before), "a thread outlived the test"


def _config(tmp_path: Path, robot_section: str) -> Path:
    p = tmp_path / "run.yaml"
    p.write_text("backend: robot\nrate_hz: 20\nrobot:\n" + robot_section)
    return p


def test_uvc_video_file_with_base_and_gripper_fakes(tmp_path: Path, video: Path,
                                                    fakes: tuple[KobukiFake, FakeRobotiq]) -> None:
    base, grip = fakes
    cfg = _config(tmp_path,
                  f"  base: {{kind: kobuki, port: {base.port}, start: [1.0, 2.0, 0.5]}}\n"
                  f"  gripper: {{kind: robotiq_rtu, port: {grip.port}}}\n"
                  "  camera:\n    kind: uvc\n"
                  f"    device: {video}\n    width: {W}\n    height: {H}\n    fps: 10\n"
                  "    intrinsics: {fx: 50.0, fy: 51.0, cx: 31.5, cy: 23.5, dist: [0.1, 0, 0, 0, 0]}\n"
                  "    frame_timeout: 60.0\n"
                  "    pose_in_base: {xyz: [0.1, 0.02, 0.56], rpy: [-1.5707963, 0.0, -1.5707963]}\n")
    loaded = load_config(cfg)
    assert rb.check(loaded.section()) == [
        f"base: kobuki on {base.port}", f"gripper: robotiq on {grip.port}", f"camera: uvc {video}",
    ]
    robot = build_robot(loaded)
    try:
        assert robot.camera is not None and robot.gripper is not None and robot.base is not None
        frame = _wait(robot.camera.frame)
        assert isinstance(frame, CameraFrame), "no camera frame within 5 s"
        intr = frame.intrinsics
        assert (intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy) == (W, H, 50.0, 51.0, 31.5, 23.5)
        assert intr.dist == (0.1, 0.0, 0.0, 0.0, 0.0)
        assert robot.camera.intrinsics == intr
        assert frame.rgb.shape == (H, W, 3) and frame.depth is None
        assert np.abs(frame.rgb[H // 2, W // 2].astype(int) - (200, 40, 10)).max() < 12  # RGB order
        # mount: optical z (forward) along the base's +x, optical x (right) along -y
        T = frame.T_base_camera
        assert T[:3, 3] == pytest.approx([0.1, 0.02, 0.56])
        assert T[:3, 2] == pytest.approx([1.0, 0.0, 0.0], abs=1e-6)
        assert T[:3, 0] == pytest.approx([0.0, -1.0, 0.0], abs=1e-6)
        assert robot.camera.pose_in_base() == pytest.approx(T)
        # T_map_base is the base's odometry at grab time (start pose, robot at rest)
        assert frame.T_map_base[:3, 3] == pytest.approx([1.0, 2.0, 0.0], abs=1e-3)
        assert math.atan2(frame.T_map_base[1, 0], frame.T_map_base[0, 0]) == pytest.approx(0.5, abs=1e-3)
    finally:
        robot.close()
    assert robot.camera.frame() is None or robot.camera.health().frames > 0


def test_locobot_hfov_gives_square_pixel_intrinsics(tmp_path: Path, video: Path) -> None:
    cfg = _config(tmp_path, f"  camera: {{kind: uvc, device: {video}, width: {W}, height: {H}, "
                            "hfov: 0.994837, frame_timeout: 60.0}\n")
    robot = build_robot(load_config(cfg))
    try:
        frame = _wait(robot.camera.frame) if robot.camera is not None else None
        assert isinstance(frame, CameraFrame)
        f = (W / 2) / math.tan(0.994837 / 2)
        assert frame.intrinsics.fx == pytest.approx(f) and frame.intrinsics.fy == pytest.approx(f)
        assert (frame.intrinsics.cx, frame.intrinsics.cy) == ((W - 1) / 2, (H - 1) / 2)
        assert frame.T_map_base == pytest.approx(np.eye(4))  # no base configured
    finally:
        robot.close()


def test_realsense_without_pyrealsense2_is_one_line_error_before_any_device(
        tmp_path: Path, fakes: tuple[KobukiFake, FakeRobotiq]) -> None:
    assert importlib.util.find_spec("pyrealsense2") is None, "this test needs pyrealsense2 absent"
    base, _grip = fakes
    cfg = _config(tmp_path, f"  base: {{kind: kobuki, port: {base.port}}}\n"
                            "  camera: {kind: realsense, width: 640, height: 480}\n")
    loaded = load_config(cfg)
    assert rb.check(loaded.section()) == [f"base: kobuki on {base.port}", "camera: realsense 0"]
    with pytest.raises(InputError) as ei:
        build_robot(loaded)
    msg = str(ei.value)
    assert msg == (f"{cfg}:5:11: robot.camera: realsense 0: pyrealsense2 is not installed: "
                   "pip install mmexec[realsense]")
    # the base was never opened: the fake saw no command
    snap = base.snapshot()
    assert snap.base_control_frames == 0 and snap.requests == []


def test_bad_camera_sections_are_positioned(tmp_path: Path) -> None:
    cfg = _config(tmp_path,
                  "  camera:\n    kind: uvc\n    device: 0\n    widht: 640\n    fps: -1\n"
                  "    mount_link: tol0\n"
                  "  gripper:\n    kind: robotiq_rtu\n    port: /dev/null\n")
    with pytest.raises(InputError) as ei:
        rb.check(load_config(cfg).section())
    text = str(ei.value)
    assert f"{cfg}:7:5: robot.camera.widht: unknown key; did you mean 'width'?" in text.splitlines()
    cfg2 = _config(tmp_path, "  camera:\n    kind: uvc\n    fps: -1\n    mount_link: tol0\n")
    with pytest.raises(InputError) as ei:
        rb.check(load_config(cfg2).section())
    lines = str(ei.value).splitlines()
    assert f"{cfg2}:6:10: robot.camera.fps: fps must be > 0, got -1.0" in lines
    assert f"{cfg2}:5:5: robot.camera: a uvc camera needs 'intrinsics' (fx, fy, cx, cy) or 'hfov' [rad]" in lines
    assert f"{cfg2}:7:17: robot.camera.mount_link: unknown link 'tol0'; did you mean 'tool0'?" in lines
    cfg3 = _config(tmp_path, "  camera: {kind: realsense, mount_link: tool0}\n")
    with pytest.raises(InputError, match=r"run\.yaml:4:41: robot\.camera\.mount_link: 'tool0' needs "
                                         r"'arm: \{kind: ur\}'"):
        rb.check(load_config(cfg3).section())


def test_missing_video_file_names_the_device(tmp_path: Path) -> None:
    cfg = _config(tmp_path, "  camera: {kind: uvc, device: /no/such/video.avi, hfov: 1.0}\n")
    with pytest.raises(InputError) as ei:
        build_robot(load_config(cfg))
    assert str(ei.value) == f"{cfg}:4:11: robot.camera: camera /no/such/video.avi: no such device or file"


def test_ur5e_wrist_camera_follows_the_arm(video: Path) -> None:
    from mmexec.drivers.ur.arm import URArm, URArmConfig
    from mmexec.drivers.ur.fake import FakeURController

    clock = ManualClock()
    ctrl = FakeURController(clock, q0=(0.0,) * 6)
    arm = URArm(URArmConfig(host="fake-ur", connect_timeout=1.0), clock=clock,
                control_factory=ctrl.control_factory, receive_factory=ctrl.receive_factory)
    robot = rb.RealRobot("ur", {}, clock=clock)
    arm.open()
    robot.arm = arm
    robot.add_closer("ur", arm.close)
    cam = UVCCamera(CameraConfig(device=str(video), width=W, height=H, hfov=1.0, frame_timeout=60.0,
                                 pose_in_base=MountConfig((0.0, 0.0, 0.04))),
                    clock=clock, link_pose=functools.partial(rb._ur_tool0_in_base, robot, "ur5e"))
    try:
        assert _wait(lambda: arm.state().positions == (0.0,) * 6)
        # UR5e zero pose (docs/robots.md 2.1/2.3): tool0 at (a2 + a3, d4 + d6, d1 - d5) with x, y
        # flipped into base_link, its z axis along base_link +y; the camera 0.04 m out on z
        tool0 = np.array([0.425 + 0.3922, 0.1333 + 0.0996, 0.1625 - 0.0997])
        T = cam.pose_in_base()
        assert T[:3, 3] == pytest.approx(tool0 + [0.0, 0.04, 0.0], abs=1e-6)
        assert T[:3, 2] == pytest.approx([0.0, 1.0, 0.0], abs=1e-6)
        cam.open()
        robot.add_closer("camera", cam.close)
        frame = _wait(cam.frame)
        assert isinstance(frame, CameraFrame) and frame.T_base_camera == pytest.approx(T)
    finally:
        robot.close()


def _shipped_camera(name: str) -> tuple[CameraConfig, str]:
    from mmexec.config.yamlload import Problems, bind, load_yaml

    section = load_yaml(Path(__file__).resolve().parents[2] / "config" / name)["robot"]["camera"]
    cam_part, link_part = rb._split(rb._without(section, "kind"), CameraConfig, rb._MountLink)
    problems = Problems()
    cam, link = bind(CameraConfig, cam_part, section.mark, "camera", problems), \
        bind(rb._MountLink, link_part, section.mark, "camera", problems)
    problems.raise_if_any()
    assert cam is not None and link is not None and cam.problems() == []
    return cam, link.mount_link


def test_shipped_locobot_camera_is_the_d435_at_pan_tilt_zero() -> None:
    cam, link = _shipped_camera("locobot.yaml")
    assert link == "head" and (cam.width, cam.height) == (640, 480)  # the pose at pan = tilt = 0, moved by the head
    intr = cam.camera_intrinsics()
    assert intr is not None and intr.fx == pytest.approx(589.367, abs=1e-3) and intr.fx == intr.fy
    # docs/robots.md 1.2: camera_depth_link in base_footprint, quat (x, y, z, w) = (-0.5, 0.5, -0.5, 0.5)
    x, y, z, w = -0.5, 0.5, -0.5, 0.5
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    T = cam.pose_in_base.matrix()
    assert T[:3, :3] == pytest.approx(R, abs=1e-6)
    assert T[:3, 3] == pytest.approx([0.101445, 0.017456, 0.561689])


def test_shipped_ur5e_camera_rides_on_tool0() -> None:
    cam, link = _shipped_camera("ur5e.yaml")
    assert link == "tool0" and cam.intrinsics is None and cam.hfov is None  # factory calibration
