"""Synthetic camera views of an ArUco marker on a wall, with exact ground truth.

Used by the tests and the perception benchmark (and handy for trying detector settings):
the marker image from ``cv2.aruco.generateImageMarker`` (with a white quiet zone) is
warped by the homography of a pinhole camera onto a textured background; the depth
image is the exact ray/plane intersection with the wall the marker hangs on.

Frames: ``T_camera_marker`` is the marker pose in the camera optical frame (z forward,
x right, y down); the marker frame is OpenCV's (origin at the centre, x right, y up as
printed, z out of the face towards the camera).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from mmexec.drivers.geometry import rot_x, rot_y, rot_z
from mmexec.drivers.interfaces import CameraIntrinsics

__all__ = ["SyntheticView", "look_at_marker", "render_marker_view", "render_markers_view"]


@dataclass(frozen=True)
class SyntheticView:
    """A rendered view: ``rgb`` HxWx3 uint8, ``depth`` HxW float32 [m] (nan off the wall),
    and the ground-truth corner pixels (TL, TR, BR, BL) of the marker's black square."""

    rgb: np.ndarray
    depth: np.ndarray
    corners: np.ndarray


def look_at_marker(distance: float, yaw: float = 0.0, pitch: float = 0.0, roll: float = 0.0,
                   offset: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """``T_camera_marker`` for a marker ``distance`` [m] in front of the camera, seen
    head-on and then turned by ``yaw`` (about its y, up), ``pitch`` (about its x) and
    ``roll`` (about its z) [rad], shifted by ``offset`` (x right, y down) [m]."""
    # head-on: marker z towards the camera (-z_cam), marker y up (-y_cam), x right (x_cam)
    R0 = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    R = R0 @ rot_y(yaw) @ rot_x(pitch) @ rot_z(roll)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = (offset[0], offset[1], distance)
    return T


def _project(K: np.ndarray, T: np.ndarray, pts: np.ndarray) -> np.ndarray:
    pc = (T[:3, :3] @ pts.T).T + T[:3, 3]
    uv = (K @ pc.T).T
    return uv[:, :2] / uv[:, 2:3]


def render_marker_view(
    intrinsics: CameraIntrinsics,
    T_camera_marker: np.ndarray,
    marker_id: int,
    marker_length: float,
    *,
    dictionary: int = cv2.aruco.DICT_4X4_50,
    noise_sigma: float = 0.0,
    depth_noise_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
    texture: bool = True,
    marker_pixels: int = 600,
    supersample: int = 4,
) -> SyntheticView:
    """Render the marker (side ``marker_length`` [m], black square only) on a grey wall.

    ``noise_sigma``: Gaussian pixel noise [grey levels]; ``depth_noise_sigma`` [m];
    ``supersample``: rendering oversampling per axis (edges area-averaged). The
    camera must see the marker's front (marker z towards the camera).
    """
    return render_markers_view(intrinsics, [(T_camera_marker, marker_id)], marker_length, dictionary=dictionary,
                                noise_sigma=noise_sigma, depth_noise_sigma=depth_noise_sigma, rng=rng,
                                texture=texture, marker_pixels=marker_pixels, supersample=supersample)


def render_markers_view(
    intrinsics: CameraIntrinsics,
    markers: Sequence[tuple[np.ndarray, int]],
    marker_length: float,
    *,
    dictionary: int = cv2.aruco.DICT_4X4_50,
    noise_sigma: float = 0.0,
    depth_noise_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
    texture: bool = True,
    marker_pixels: int = 600,
    supersample: int = 4,
) -> SyntheticView:
    """Render several markers ``[(T_camera_marker, id), ...]`` (each on its own plane,
    drawn in the given order) on a textured background; markers behind the camera or
    facing away are left out. Depth is the ray/plane intersection with the plane of the
    marker whose tile covers the pixel, elsewhere with the first marker's plane (the
    wall). ``corners`` are those of the first marker (NaN when it is not drawn)."""
    rng = rng if rng is not None else np.random.default_rng(0)
    K = intrinsics.matrix()
    W, H = intrinsics.width, intrinsics.height
    border = marker_pixels // 6  # white quiet zone, one module-ish wide
    half = marker_length / 2.0
    q = half * (marker_pixels + 2 * border) / marker_pixels
    obj_quiet = np.array([[-q, q, 0], [q, q, 0], [q, -q, 0], [-q, -q, 0]], dtype=float)
    obj_black = np.array([[-half, half, 0], [half, half, 0], [half, -half, 0], [-half, -half, 0]], dtype=float)
    # render at ``supersample`` x resolution and area-average down, like a real sensor
    # integrating light over each pixel (point-sampled hard edges bias corner refinement)
    ss = max(1, int(supersample))
    Ks = K.copy()
    Ks[0, 0], Ks[1, 1] = K[0, 0] * ss, K[1, 1] * ss
    Ks[0, 2], Ks[1, 2] = (K[0, 2] + 0.5) * ss - 0.5, (K[1, 2] + 0.5) * ss - 0.5

    if texture:
        base = rng.integers(90, 200, size=(H // 16 + 1, W // 16 + 1), dtype=np.uint8)
        bg = cv2.resize(base, (W, H), interpolation=cv2.INTER_CUBIC)
        bg = cv2.GaussianBlur(bg, (0, 0), 3.0)
    else:
        bg = np.full((H, W), 150, np.uint8)
    gray = bg.astype(np.float32)
    owner = np.full((H, W), -1, np.int32)   # which marker's plane each pixel shows
    drawn: list[bool] = []
    for k, (T, marker_id) in enumerate(markers):
        if not _faces_camera(T, obj_quiet):
            drawn.append(False)
            continue
        img_m = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(dictionary), int(marker_id),
                                              marker_pixels)
        tile = np.full((marker_pixels + 2 * border, marker_pixels + 2 * border), 255, np.uint8)
        tile[border:-border, border:-border] = img_m
        dst = _project(Ks, T, obj_quiet).astype(np.float32)
        n = tile.shape[0]
        src = np.array([[0, 0], [n, 0], [n, n], [0, n]], dtype=np.float32) - 0.5
        Hm = cv2.getPerspectiveTransform(src, dst)
        warped = cv2.warpPerspective(tile, Hm, (W * ss, H * ss), flags=cv2.INTER_LINEAR, borderValue=0)
        mask = cv2.warpPerspective(np.full_like(tile, 255), Hm, (W * ss, H * ss), flags=cv2.INTER_LINEAR, borderValue=0)
        if ss > 1:
            warped = cv2.resize(warped.astype(np.float32), (W, H), interpolation=cv2.INTER_AREA)
            mask = cv2.resize(mask.astype(np.float32), (W, H), interpolation=cv2.INTER_AREA)
        a = mask.astype(np.float32) / 255.0
        gray = a * warped.astype(np.float32) + (1.0 - a) * gray
        owner[a > 0.5] = k
        drawn.append(True)
    if noise_sigma > 0:
        gray = gray + rng.normal(0.0, noise_sigma, gray.shape)
    gray_u8 = np.clip(gray, 0, 255).astype(np.uint8)
    rgb = np.dstack([gray_u8, gray_u8, gray_u8])

    # depth: intersection of each pixel ray with the plane shown there
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1)
    z = np.full((H, W), np.nan)
    for k, (T, _mid) in enumerate(markers):
        if k > 0 and not drawn[k]:
            continue
        sel = owner == k if k > 0 else (owner == k) | (owner < 0)
        nrm = T[:3, 2]
        denom = rays[sel] @ nrm
        with np.errstate(divide="ignore", invalid="ignore"):
            z[sel] = (T[:3, 3] @ nrm) / denom
    z[(z <= 0) | ~np.isfinite(z)] = np.nan
    if depth_noise_sigma > 0:
        z = z + rng.normal(0.0, depth_noise_sigma, z.shape)
    if markers and drawn[0]:
        corners = _project(K, markers[0][0], obj_black).astype(np.float32)
    else:
        corners = np.full((4, 2), np.nan, np.float32)
    return SyntheticView(rgb=rgb, depth=z.astype(np.float32), corners=corners)


def _faces_camera(T_camera_marker: np.ndarray, obj: np.ndarray) -> bool:
    """Whether every corner is in front of the camera and the face points at it."""
    pc = (T_camera_marker[:3, :3] @ obj.T).T + T_camera_marker[:3, 3]
    if np.any(pc[:, 2] <= 0.01):
        return False
    return float(np.dot(T_camera_marker[:3, 2], T_camera_marker[:3, 3])) < 0.0
