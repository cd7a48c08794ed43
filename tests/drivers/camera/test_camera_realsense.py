"""RealSenseCamera's frame path against a stand-in pyrealsense2 module (no device here):
aligned depth converted to metres with the device's depth scale, 0 -> nan, factory
intrinsics when the config gives none, start failure as one clear error."""

from __future__ import annotations

import sys
import time
import types

import numpy as np
import pytest

from mmexec.drivers.camera.config import CameraConfig
from mmexec.drivers.camera.errors import CameraError


class _Frame:
    def __init__(self, data: np.ndarray) -> None:
        self.data = data

    def get_data(self) -> np.ndarray:
        return self.data

    def __bool__(self) -> bool:
        return True


class _Frames:
    def __init__(self, color: np.ndarray, depth: np.ndarray) -> None:
        self.color, self.depth = color, depth

    def get_color_frame(self) -> _Frame:
        return _Frame(self.color)

    def get_depth_frame(self) -> _Frame:
        return _Frame(self.depth)


def fake_rs(fail_start: bool = False) -> types.ModuleType:
    rs = types.ModuleType("pyrealsense2")
    rs.stream = types.SimpleNamespace(color="color", depth="depth")  # type: ignore[attr-defined]
    rs.format = types.SimpleNamespace(rgb8="rgb8", z16="z16")  # type: ignore[attr-defined]
    state: dict[str, object] = {"enabled": [], "aligned_to": None, "stopped": False}
    rs.state = state  # type: ignore[attr-defined]

    class config:
        def enable_stream(self, *args: object) -> None:
            state["enabled"].append(args)  # type: ignore[attr-defined]

        def enable_device(self, serial: str) -> None:
            state["serial"] = serial

    intr = types.SimpleNamespace(width=4, height=2, fx=1.5, fy=1.6, ppx=1.0, ppy=0.5,
                                 coeffs=[0.01, 0, 0, 0, 0])
    profile = types.SimpleNamespace(
        get_device=lambda: types.SimpleNamespace(first_depth_sensor=lambda: types.SimpleNamespace(
            get_depth_scale=lambda: 0.001)),
        get_stream=lambda s: types.SimpleNamespace(
            as_video_stream_profile=lambda: types.SimpleNamespace(get_intrinsics=lambda: intr)))

    class pipeline:
        def start(self, cfg: config) -> object:
            if fail_start:
                raise RuntimeError("No device connected")
            return profile

        def try_wait_for_frames(self, timeout_ms: int) -> tuple[bool, _Frames | None]:
            time.sleep(0.002)
            color = np.zeros((2, 4, 3), np.uint8)
            color[0, 0] = (10, 20, 30)
            depth = np.array([[0, 1000, 1500, 2000], [250, 0, 0, 65535]], np.uint16)
            return True, _Frames(color, depth)

        def stop(self) -> None:
            state["stopped"] = True

    class align:
        def __init__(self, to: str) -> None:
            state["aligned_to"] = to

        def process(self, frames: _Frames) -> _Frames:
            return frames

    rs.config, rs.pipeline, rs.align = config, pipeline, align  # type: ignore[attr-defined]
    return rs


def test_aligned_depth_in_metres(monkeypatch: pytest.MonkeyPatch) -> None:
    rs = fake_rs()
    monkeypatch.setitem(sys.modules, "pyrealsense2", rs)
    from mmexec.drivers.camera.realsense import RealSenseCamera

    cam = RealSenseCamera(CameraConfig(device="123456", width=4, height=2, fps=30.0))
    with pytest.raises(CameraError, match=r"call open\(\) first"):
        _ = cam.intrinsics
    with cam:
        deadline = time.monotonic() + 2.0
        while cam.frame() is None and time.monotonic() < deadline:
            time.sleep(0.005)
        f = cam.frame()
        assert f is not None and f.depth is not None
        assert f.depth.dtype == np.float32
        assert np.isnan(f.depth[0, 0]) and np.isnan(f.depth[1, 1])
        assert f.depth[0, 1] == pytest.approx(1.0) and f.depth[0, 3] == pytest.approx(2.0)
        assert f.depth[1, 0] == pytest.approx(0.25)
        assert tuple(f.rgb[0, 0]) == (10, 20, 30)
        assert (f.intrinsics.fx, f.intrinsics.cx, f.intrinsics.dist[0]) == (1.5, 1.0, 0.01)
    assert rs.state["aligned_to"] == "color" and rs.state["stopped"]  # type: ignore[attr-defined]
    assert rs.state["serial"] == "123456"  # type: ignore[attr-defined]
    assert ("depth", 4, 2, "z16", 30) in rs.state["enabled"]  # type: ignore[attr-defined]


def test_start_failure_is_one_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pyrealsense2", fake_rs(fail_start=True))
    from mmexec.drivers.camera.realsense import RealSenseCamera

    cam = RealSenseCamera(CameraConfig(device=0))
    with pytest.raises(CameraError, match=r"^realsense 0: cannot start \(No device connected\)"):
        cam.open()
