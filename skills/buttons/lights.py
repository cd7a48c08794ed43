"""Is a panel light on? Read from a camera frame, as a robot would.

The light's centre is known in ``map`` (the panel fit and the layout); it is projected into
the frame through the frame's own camera pose (``T_map_base @ T_base_camera``), and the
pixels inside ``radius`` [m] of it (projected at its depth) are compared with the colour
of a lit lamp: a lit light is green, so its pixels' green level exceeds both red and blue
by ``contrast`` levels (0-255) on the median pixel. An unlit lamp is dark grey (no green
excess). The median keeps a few pixels of the rim or the face from deciding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mmexec.drivers.interfaces import CameraFrame

__all__ = ["LightReading", "read_light"]


@dataclass(frozen=True)
class LightReading:
    """``on`` (None: the light is not in the image, behind the camera or too small);
    ``excess``: the median pixel's green minus max(red, blue) [levels]; ``pixels`` read;
    ``uv`` the projected centre [px]."""

    on: bool | None
    excess: float
    pixels: int
    uv: tuple[float, float] | None


def read_light(frame: CameraFrame, centre_map: np.ndarray, radius: float, contrast: float,
               min_pixels: int = 12) -> LightReading:
    """Read the light centred at ``centre_map`` [m, map] of ``radius`` [m] in ``frame``."""
    T_map_cam = np.asarray(frame.T_map_base) @ np.asarray(frame.T_base_camera)
    pc = np.linalg.inv(T_map_cam) @ np.append(np.asarray(centre_map, dtype=float), 1.0)
    z = float(pc[2])
    if z <= 0.05:
        return LightReading(None, 0.0, 0, None)
    K = frame.intrinsics
    u, v = K.fx * pc[0] / z + K.cx, K.fy * pc[1] / z + K.cy
    r_px = K.fx * radius / z
    h, w = frame.rgb.shape[:2]
    if not (r_px <= u < w - r_px and r_px <= v < h - r_px):
        return LightReading(None, 0.0, 0, (float(u), float(v)))
    y0, y1 = int(np.floor(v - r_px)), int(np.ceil(v + r_px)) + 1
    x0, x1 = int(np.floor(u - r_px)), int(np.ceil(u + r_px)) + 1
    yy, xx = np.mgrid[y0:y1, x0:x1]
    inside = (xx - u) ** 2 + (yy - v) ** 2 <= r_px * r_px
    px = frame.rgb[y0:y1, x0:x1][inside].astype(float)
    if len(px) < min_pixels:
        return LightReading(None, 0.0, len(px), (float(u), float(v)))
    excess = px[:, 1] - np.maximum(px[:, 0], px[:, 2])
    med = float(np.median(excess))
    return LightReading(med >= contrast, med, len(px), (float(u), float(v)))
