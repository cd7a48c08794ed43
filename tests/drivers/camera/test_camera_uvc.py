"""UVCCamera against a fake capture source and a real video file; config and RealSense."""

from __future__ import annotations

import math
import sys
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from driverkit import wait_for

from mmexec.config.yamlload import InputError
from mmexec.drivers.camera.config import (
    CameraConfig,
    IntrinsicsConfig,
    MountConfig,
    load_camera_config,
)
from mmexec.drivers.camera.errors import CameraError
from mmexec.drivers.camera.uvc import UVCCamera
from mmexec.drivers.interfaces import ManualClock


class FakeCapture:
    """A scripted capture: serves queued BGR frames, then reports no frame (a dropout)."""

    def __init__(self, opened: bool = True) -> None:
        self.opened = opened
        self.frames: list[np.ndarray] = []
        self.lock = threading.Lock()
        self.settings: dict[int, float] = {}
        self.released = False

    def isOpened(self) -> bool:
        return self.opened

    def set(self, prop: int, value: float) -> bool:
        self.settings[prop] = value
        return True

    def read(self) -> tuple[bool, np.ndarray | None]:
        time.sleep(0.002)  # a real device blocks for a frame period
        with self.lock:
            if self.frames:
                return True, self.frames.pop(0)
        return False, None

    def release(self) -> None:
        self.released = True

    def push(self, bgr: np.ndarray) -> None:
        with self.lock:
            self.frames.append(bgr)


def bgr(w: int, h: int, b: int, g: int, r: int) -> np.ndarray:
    return np.full((h, w, 3), (b, g, r), np.uint8)


CFG = CameraConfig(device=3, width=64, height=48, hfov=math.radians(60.0), frame_timeout=0.5,
                   pose_in_base=MountConfig((0.1, 0.0, 0.5), (-math.pi / 2, 0.0, -math.pi / 2)))


def test_frames_rgb_intrinsics_pose_and_dropout() -> None:
    cap = FakeCapture()
    clock = ManualClock(10.0)
    cam = UVCCamera(CFG, clock=clock, capture_factory=lambda dev: cap)
    assert cam.frame() is None                          # not open: no frame, no block
    with cam:
        assert cap.settings[cv2.CAP_PROP_FRAME_WIDTH] == 64
        assert cam.frame() is None                      # before the first frame
        cap.push(bgr(64, 48, 255, 0, 0))                # pure blue in BGR
        assert wait_for(lambda: cam.frame() is not None)
        f = cam.frame()
        assert f is not None and f.rgb.shape == (48, 64, 3)
        assert tuple(f.rgb[0, 0]) == (0, 0, 255)        # delivered as RGB
        assert f.depth is None and f.stamp == 10.0
        fx = 32.0 / math.tan(math.radians(30.0))
        assert f.intrinsics.fx == pytest.approx(fx) and f.intrinsics.cx == pytest.approx(31.5)
        # mount: optical z along base x, optical x along base -y, optical y along base -z
        T = cam.pose_in_base()
        assert np.allclose(T[:3, 2], (1, 0, 0)) and np.allclose(T[:3, 0], (0, -1, 0))
        assert np.allclose(T[:3, 1], (0, 0, -1)) and np.allclose(T[:3, 3], (0.1, 0, 0.5))
        clock.advance(0.4)
        assert cam.frame() is f                          # 0.4 s old: still fresh
        clock.advance(0.2)
        assert cam.frame() is None                       # 0.6 s old: dropout
        h = cam.health()
        assert h.dropout and h.frames == 1 and h.age == pytest.approx(0.6)
        cap.push(bgr(64, 48, 0, 255, 0))                 # the device comes back
        assert wait_for(lambda: cam.frame() is not None)
        assert tuple(cam.frame().rgb[0, 0]) == (0, 255, 0)  # type: ignore[union-attr]
        assert not cam.health().dropout
    assert cap.released


def test_wrong_frame_size_is_reported_not_served() -> None:
    cap = FakeCapture()
    cam = UVCCamera(CFG, clock=ManualClock(), capture_factory=lambda dev: cap)
    with cam:
        cap.push(bgr(640, 480, 0, 0, 0))
        assert wait_for(lambda: cam.health().error != "")
        assert cam.health().error == ("camera 3: delivers 640x480 frames but the intrinsics "
                                      "are for 64x48: fix width/height in the config")
        assert cam.frame() is None


def test_open_failure_names_the_device() -> None:
    cap = FakeCapture(opened=False)
    cam = UVCCamera(CFG, capture_factory=lambda dev: cap)
    with pytest.raises(CameraError, match=r"^camera 3: cannot open \(no such device"):
        cam.open()
    assert cap.released
    missing = UVCCamera(CameraConfig(device="/dev/video-none", hfov=1.0))
    with pytest.raises(CameraError, match="^camera /dev/video-none: no such device or file$"):
        missing.open()


def test_needs_intrinsics_or_fov() -> None:
    with pytest.raises(CameraError, match="needs intrinsics"):
        UVCCamera(CameraConfig(device=0))
    with pytest.raises(CameraError, match="either intrinsics or hfov"):
        UVCCamera(CameraConfig(device=0, hfov=1.0,
                               intrinsics=IntrinsicsConfig(500, 500, 320, 240)))


def test_video_file_end_to_end(tmp_path: Path) -> None:
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (64, 48))
    assert writer.isOpened()
    for i in range(4):
        writer.write(bgr(64, 48, 0, 60 * i, 200))
    writer.release()
    cfg = CameraConfig(device=str(path), width=64, height=48,
                       intrinsics=IntrinsicsConfig(80.0, 81.0, 31.0, 23.0, (0.1, 0, 0, 0, 0)),
                       frame_timeout=0.2)
    cam = UVCCamera(cfg)
    with cam:
        assert wait_for(lambda: cam.health().frames == 4)
        f = cam.frame()
        assert f is not None
        r, g, b = (int(v) for v in f.rgb[10, 10])
        assert abs(r - 200) < 8 and abs(g - 180) < 8 and b < 8   # the last frame, as RGB
        assert f.intrinsics.fy == 81.0 and f.intrinsics.dist[0] == 0.1
        # end of file: the device stopped delivering -> None after the timeout
        assert wait_for(lambda: cam.frame() is None, 1.0)
        assert cam.health().dropout


def test_config_from_yaml(tmp_path: Path) -> None:
    good = tmp_path / "cam.yaml"
    good.write_text("camera:\n  device: 0\n  width: 640\n  height: 480\n"
                    "  intrinsics: {fx: 615.0, fy: 615.5, cx: 319.5, cy: 239.5}\n"
                    "  pose_in_base: {xyz: [0.1, 0.0, 0.5], rpy: [0.0, 0.5, 0.0]}\n")
    cfg = load_camera_config(good, "camera")
    intr = cfg.camera_intrinsics()
    assert intr is not None and (intr.fx, intr.fy, intr.width) == (615.0, 615.5, 640)
    assert cfg.pose_in_base.matrix()[0, 2] == pytest.approx(math.sin(0.5))
    bad = tmp_path / "bad.yaml"
    bad.write_text("device: 0\nhfov: 4.0\nwidht: 640\n")
    with pytest.raises(InputError) as e:
        load_camera_config(bad)
    assert "bad.yaml:3:1" in str(e.value) and "widht" in str(e.value)
    bad.write_text("device: 0\nhfov: 4.0\n")
    with pytest.raises(InputError, match=r"bad.yaml:2:7: hfov: hfov must be in \(0, pi\)"):
        load_camera_config(bad)


def test_realsense_absent_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pyrealsense2", None)   # import fails as when absent
    from mmexec.drivers.camera.realsense import RealSenseCamera

    with pytest.raises(CameraError) as e:
        RealSenseCamera(CameraConfig())
    assert str(e.value) == "pyrealsense2 is not installed: pip install mmexec[realsense]"
