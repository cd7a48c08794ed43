"""RGB-D from an Intel RealSense (D435 on the LoCoBot) through ``pyrealsense2``, optional.

``pyrealsense2`` is imported when a :class:`RealSenseCamera` is constructed; without it the
constructor raises :class:`CameraError` "pyrealsense2 is not installed: pip install
mmexec[realsense]". Depth is aligned to the colour stream (``rs.align``) and converted to
float32 metres along the optical z axis with the device's depth scale; 0 (no data) becomes
``nan``. Intrinsics are the config's if given, else the colour stream's factory calibration.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np

from mmexec.drivers.camera.config import CameraConfig
from mmexec.drivers.camera.errors import CameraError
from mmexec.drivers.camera.grabber import GrabbingCamera
from mmexec.drivers.interfaces import CameraIntrinsics, Clock

__all__ = ["RealSenseCamera"]

log = logging.getLogger(__name__)

INSTALL_HINT = "pyrealsense2 is not installed: pip install mmexec[realsense]"


class RealSenseCamera(GrabbingCamera):
    """RGB-D camera capability on a RealSense. ``config.device`` is the serial number
    (a string) or 0 for the first device found. Construction does no I/O."""

    def __init__(self, config: CameraConfig, *, clock: Clock | None = None,
                 base_pose: Callable[[], np.ndarray] | None = None,
                 link_pose: Callable[[], np.ndarray] | None = None,
                 wait_ms: int = 200) -> None:
        try:
            import pyrealsense2 as rs
        except ImportError as e:
            raise CameraError(INSTALL_HINT) from e
        problems = config.problems()
        if problems:
            field, message = problems[0]
            raise CameraError(f"realsense {config.device}: {field}: {message}")
        super().__init__(f"realsense {config.device}", config.camera_intrinsics(),
                         config.pose_in_base.matrix(), config.frame_timeout, clock, base_pose, link_pose)
        self.config = config
        self._rs: Any = rs
        self._wait_ms = wait_ms
        self._pipeline: Any = None
        self._align: Any = None
        self._depth_scale = 0.0

    def _open_device(self) -> None:
        rs, cfg = self._rs, self.config
        pipeline = rs.pipeline()
        rcfg = rs.config()
        if isinstance(cfg.device, str) and cfg.device not in ("", "0"):
            rcfg.enable_device(cfg.device)
        fps = round(cfg.fps)
        rcfg.enable_stream(rs.stream.color, cfg.width, cfg.height, rs.format.rgb8, fps)
        rcfg.enable_stream(rs.stream.depth, cfg.width, cfg.height, rs.format.z16, fps)
        try:
            profile = pipeline.start(rcfg)
        except RuntimeError as e:
            raise CameraError(f"{self.name}: cannot start ({e}): is it plugged into USB 3 "
                              "and not used by another program?") from e
        self._depth_scale = float(profile.get_device().first_depth_sensor().get_depth_scale())
        self._align = rs.align(rs.stream.color)
        if self._intrinsics is None:
            ci = profile.get_stream(rs.stream.color).as_video_stream_profile().get_intrinsics()
            self._intrinsics = CameraIntrinsics(int(ci.width), int(ci.height), float(ci.fx),
                                                float(ci.fy), float(ci.ppx), float(ci.ppy),
                                                tuple(float(c) for c in ci.coeffs))
        self._pipeline = pipeline
        log.info("%s: streaming %dx%d, depth scale %g m", self.name, cfg.width, cfg.height,
                 self._depth_scale)

    def _grab(self) -> tuple[np.ndarray, np.ndarray | None] | None:
        pipeline = self._pipeline
        if pipeline is None:
            return None
        try:
            ok, frames = pipeline.try_wait_for_frames(self._wait_ms)
        except RuntimeError as e:
            raise CameraError(f"{self.name}: stream failed ({e})") from e
        if not ok:
            return None
        aligned = self._align.process(frames)
        color, depth = aligned.get_color_frame(), aligned.get_depth_frame()
        if not color or not depth:
            return None
        rgb = np.array(np.asanyarray(color.get_data()), dtype=np.uint8, copy=True)
        z = np.asanyarray(depth.get_data()).astype(np.float32) * np.float32(self._depth_scale)
        z[z == 0] = np.nan
        return rgb, z

    def _close_device(self) -> None:
        pipeline, self._pipeline = self._pipeline, None
        if pipeline is not None:
            try:
                pipeline.stop()
            except RuntimeError as e:
                log.warning("%s: stop failed: %s", self.name, e)
