"""Camera configuration: device, mode, intrinsics (explicit or from a FOV), mount pose.

YAML shape (one mapping; see docs/drivers/camera.md)::

    device: 0                 # /dev/video index, a device path or a video file
    width: 640                # px
    height: 480               # px
    fps: 30.0
    intrinsics: {fx: 615.0, fy: 615.0, cx: 319.5, cy: 239.5, dist: [0, 0, 0, 0, 0]}
    # or, instead of intrinsics:  hfov: 1.2043   (horizontal field of view [rad])
    pose_in_base: {xyz: [0.1, 0.0, 0.5], rpy: [-1.5708, 0.0, -1.5708]}
    frame_timeout: 0.5        # s without a new frame before frame() returns None

``pose_in_base`` is the pose of the camera's *optical* frame (z forward, x right, y down)
in ``base_link``: ``xyz`` [m] and roll-pitch-yaw [rad] applied as R = Rz(yaw) Ry(pitch)
Rx(roll). A camera looking straight ahead along the base's x axis has rpy
(-pi/2, 0, -pi/2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mmexec.config.yamlload import (
    InputError,
    Mark,
    Problems,
    YDict,
    bind,
    load_yaml,
    mark_of,
)
from mmexec.drivers.geometry import xyz_rpy_transform
from mmexec.drivers.interfaces import CameraIntrinsics

__all__ = ["CameraConfig", "IntrinsicsConfig", "MountConfig", "load_camera_config"]


@dataclass(frozen=True)
class IntrinsicsConfig:
    """Pinhole intrinsics [px] and OpenCV distortion coefficients."""

    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class MountConfig:
    """Optical frame pose in ``base_link``: ``xyz`` [m], ``rpy`` [rad] (R = Rz Ry Rx)."""

    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """``T_base_camera`` (4x4)."""
        return xyz_rpy_transform(self.xyz, self.rpy)


@dataclass(frozen=True)
class CameraConfig:
    """One camera. Exactly one of ``intrinsics`` and ``hfov`` [rad] for a UVC camera; a
    RealSense may give neither (then the device's factory calibration is used)."""

    device: int | str = 0
    width: int = 640
    height: int = 480
    fps: float = 30.0
    intrinsics: IntrinsicsConfig | None = None
    hfov: float | None = None
    pose_in_base: MountConfig = field(default_factory=MountConfig)
    frame_timeout: float = 0.5

    def problems(self) -> list[tuple[str, str]]:
        """(field, message) for every invalid value; empty when the config is usable."""
        out: list[tuple[str, str]] = []
        if self.width <= 0 or self.height <= 0:
            out.append(("width", f"image size {self.width}x{self.height} must be positive"))
        if not self.fps > 0:
            out.append(("fps", f"fps must be > 0, got {self.fps}"))
        if not self.frame_timeout > 0:
            out.append(("frame_timeout", f"must be > 0 s, got {self.frame_timeout}"))
        if self.intrinsics is not None and self.hfov is not None:
            out.append(("hfov", "give either intrinsics or hfov, not both"))
        if self.hfov is not None and not 0 < self.hfov < math.pi:
            out.append(("hfov", f"hfov must be in (0, pi) rad, got {self.hfov}"))
        if self.intrinsics is not None:
            i = self.intrinsics
            if not (i.fx > 0 and i.fy > 0):
                out.append(("intrinsics", f"fx and fy must be > 0 px, got {i.fx}, {i.fy}"))
            if len(i.dist) not in (4, 5, 8, 12, 14):
                out.append(("intrinsics",
                            f"dist needs 4, 5, 8, 12 or 14 coefficients, got {len(i.dist)}"))
        return out

    def camera_intrinsics(self) -> CameraIntrinsics | None:
        """Intrinsics at ``width`` x ``height`` from the explicit values or the FOV; None
        when neither is given."""
        if self.intrinsics is not None:
            i = self.intrinsics
            return CameraIntrinsics(self.width, self.height, i.fx, i.fy, i.cx, i.cy,
                                    tuple(i.dist))
        if self.hfov is not None:
            return CameraIntrinsics.from_fov(self.width, self.height, self.hfov)
        return None


def load_camera_config(path: str | Path, key: str | None = None) -> CameraConfig:
    """Load a :class:`CameraConfig` from YAML (the whole file, or the mapping under
    ``key``). Raises :class:`InputError` with ``FILE:LINE:COL: path: message`` lines."""
    data = load_yaml(path)
    start = Mark(str(path), 1, 1)
    where = key or ""
    if key is not None:
        if not isinstance(data, dict) or key not in data:
            raise InputError.at(mark_of(data, start), f"missing key {key!r}")
        data = data[key]
    problems = Problems()
    cfg = bind(CameraConfig, data, mark_of(data, start), where, problems)
    problems.raise_if_any()
    if not isinstance(cfg, CameraConfig):
        raise InputError.at(mark_of(data, start), f"{where or 'camera'}: expected a mapping")
    for name, message in cfg.problems():
        mark = data.value_mark(name) if isinstance(data, YDict) else mark_of(data, start)
        problems.add(mark, f"{where + '.' if where else ''}{name}: {message}")
    problems.raise_if_any()
    return cfg
