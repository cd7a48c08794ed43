"""RGB camera over OpenCV ``VideoCapture`` (UVC webcams, or a video file for rehearsal).

Intrinsics come from the config (explicit fx, fy, cx, cy, dist, or a horizontal FOV), the
mount pose from ``pose_in_base``. Frames are converted from OpenCV's BGR to RGB. The
capture object is made by ``capture_factory`` (default ``cv2.VideoCapture``), so tests
and tools can feed any object with ``read()``, ``isOpened()``, ``release()`` and ``set()``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from typing import Any, Protocol

import cv2
import numpy as np

from mmexec.drivers.camera.config import CameraConfig
from mmexec.drivers.camera.errors import CameraError
from mmexec.drivers.camera.grabber import GrabbingCamera
from mmexec.drivers.interfaces import Clock

__all__ = ["Capture", "UVCCamera"]

log = logging.getLogger(__name__)


class Capture(Protocol):
    """The part of ``cv2.VideoCapture`` the camera uses."""

    def isOpened(self) -> bool: ...
    def read(self) -> tuple[bool, Any]: ...
    def set(self, prop: int, value: float) -> bool: ...
    def release(self) -> None: ...


def _default_capture(device: int | str) -> Capture:
    return cv2.VideoCapture(device)  # type: ignore[return-value]


class UVCCamera(GrabbingCamera):
    """The Camera capability on a ``VideoCapture`` device. Construction does no I/O."""

    def __init__(self, config: CameraConfig, *, clock: Clock | None = None,
                 capture_factory: Callable[[int | str], Capture] | None = None,
                 base_pose: Callable[[], np.ndarray] | None = None,
                 link_pose: Callable[[], np.ndarray] | None = None) -> None:
        problems = config.problems()
        if problems:
            field, message = problems[0]
            raise CameraError(f"camera {config.device}: {field}: {message}")
        intr = config.camera_intrinsics()
        if intr is None:
            raise CameraError(f"camera {config.device}: a UVC camera needs intrinsics "
                              "(fx, fy, cx, cy) or hfov in its config")
        super().__init__(f"camera {config.device}", intr, config.pose_in_base.matrix(),
                         config.frame_timeout, clock, base_pose, link_pose)
        self.config = config
        self._factory = capture_factory or _default_capture
        self._cap: Capture | None = None

    def _device_arg(self) -> int | str:
        d = self.config.device
        return int(d) if isinstance(d, str) and d.isdigit() else d

    def _open_device(self) -> None:
        dev = self._device_arg()
        if isinstance(dev, str) and not os.path.exists(dev) and "://" not in dev:
            raise CameraError(f"{self.name}: no such device or file")
        try:
            cap = self._factory(dev)
        except cv2.error as e:
            raise CameraError(f"{self.name}: cannot open ({e})") from e
        if not cap.isOpened():
            cap.release()
            raise CameraError(f"{self.name}: cannot open (no such device, no permission, or "
                              "in use by another program)")
        cfg = self.config
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, cfg.width)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, cfg.height)
        cap.set(cv2.CAP_PROP_FPS, cfg.fps)
        self._cap = cap
        log.info("%s: open at %dx%d", self.name, cfg.width, cfg.height)

    def _grab(self) -> tuple[np.ndarray, np.ndarray | None] | None:
        cap = self._cap
        if cap is None:
            return None
        try:
            ok, bgr = cap.read()
        except cv2.error as e:
            raise CameraError(f"{self.name}: read failed ({e})") from e
        if not ok or bgr is None:
            return None
        img = np.asarray(bgr)
        if img.ndim == 2:
            return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB), None
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB), None

    def _close_device(self) -> None:
        cap, self._cap = self._cap, None
        if cap is not None:
            cap.release()
