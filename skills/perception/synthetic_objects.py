"""Synthetic RGB-D views of upright boxes and cylinders on a support plane, with exact
ground truth, for the grasp-point tests and ``benchmarks/detection.py``.

Every pixel's ray (pinhole, no distortion) is intersected with each solid as the
intersection of intervals: a box is three slabs in its own frame, an upright cylinder an
infinite cylinder and one slab in z. The nearest hit wins; the support plane ``z =
support_z`` in ``map`` lies under everything. Rays are parametrised by optical depth
(their direction has optical z = 1), so the hit parameter is the depth image's value.

:func:`spoil_depth` then spoils the depth the way a stereo camera does: noise growing
with depth (half per pixel, half spatially correlated), holes (blobs and scattered
pixels) and mixed ("flying") pixels across depth edges.

Frames: ``T_map_camera`` is the camera optical frame (x right, y down, z forward) in
``map`` (z up). An object's ``centre`` is the centre of its solid (its centre of mass
for a uniform solid) in ``map``; ``size`` is ``(sx, sy, height)`` [m] along its own
x, y (turned by ``yaw`` [rad] about map z) and z; a cylinder's is ``(2r, 2r, height)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from mmexec.drivers.interfaces import CameraIntrinsics

__all__ = [
    "BACKGROUND",
    "SUPPORT",
    "RenderedView",
    "SceneObject",
    "look_at",
    "object_box",
    "render_scene",
    "spoil_depth",
]

#: label of pixels that hit nothing
BACKGROUND = -1
#: label of pixels on the support plane
SUPPORT = -2

_LIGHT = np.array([0.3, -0.4, 0.87]) / np.linalg.norm([0.3, -0.4, 0.87])


@dataclass(frozen=True)
class SceneObject:
    """An upright ``kind`` solid: ``centre`` (3,) in ``map`` [m], ``size`` ``(sx, sy,
    height)`` [m] (a cylinder: ``(2r, 2r, height)``), ``yaw`` [rad] about map z, and its
    ``colour`` (RGB 0-255)."""

    kind: Literal["box", "cylinder"]
    centre: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw: float = 0.0
    colour: tuple[int, int, int] = (200, 40, 40)


@dataclass(frozen=True)
class RenderedView:
    """``rgb`` HxWx3 uint8, ``depth`` HxW float32 [m along optical z] (nan: no hit), and
    ``labels`` HxW int: the index of the object hit, :data:`SUPPORT` or
    :data:`BACKGROUND`."""

    rgb: np.ndarray
    depth: np.ndarray
    labels: np.ndarray


def look_at(eye: tuple[float, float, float], target: tuple[float, float, float]) -> np.ndarray:
    """``T_map_camera`` of an optical frame at ``eye`` looking at ``target`` (map [m]),
    image x horizontal (no roll)."""
    e, t = np.asarray(eye, float), np.asarray(target, float)
    z = (t - e) / np.linalg.norm(t - e)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: the view is vertical; image x is undefined")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = e
    return T


def _slab(o: np.ndarray, d: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit parameters of rays ``o + t d`` (one coordinate) through ``|x| <= half``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-half - o) / d, (half - o) / d
    lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
    inside = np.abs(o) <= half
    parallel = d == 0
    lo = np.where(parallel, np.where(inside, -np.inf, np.inf), lo)
    hi = np.where(parallel, np.where(inside, np.inf, -np.inf), hi)
    return lo, hi


def _hit(obj: SceneObject, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ray parameter of the first hit (inf: none) and the outward normal there (map)."""
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    o = R.T @ (origin - np.asarray(obj.centre, float))
    d = dirs @ R                                                           # rows: R^T d
    hz = obj.size[2] / 2.0
    entries = []
    if obj.kind == "box":
        for k in range(3):
            entries.append(_slab(np.full(len(d), o[k]), d[:, k], obj.size[k] / 2.0))
    else:
        r = obj.size[0] / 2.0
        a = d[:, 0] ** 2 + d[:, 1] ** 2
        b = 2.0 * (o[0] * d[:, 0] + o[1] * d[:, 1])
        cc = o[0] ** 2 + o[1] ** 2 - r * r
        disc = b * b - 4.0 * a * cc
        ok = (disc >= 0) & (a > 0)
        sq = np.sqrt(np.where(ok, disc, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            lo = np.where(ok, (-b - sq) / (2 * a), np.inf)
            hi = np.where(ok, (-b + sq) / (2 * a), -np.inf)
        entries.append((lo, hi))
        entries.append(_slab(np.full(len(d), o[2]), d[:, 2], hz))
    los = np.stack([e[0] for e in entries])
    his = np.stack([e[1] for e in entries])
    t_in, t_out = los.max(axis=0), his.min(axis=0)
    hit = (t_in <= t_out) & (t_in > 0)
    t = np.where(hit, t_in, np.inf)
    which = np.argmax(los, axis=0)
    p = o + np.where(hit, t, 0.0)[:, None] * d                            # hit point, object frame
    n = np.zeros_like(d)
    if obj.kind == "box":
        for k in range(3):
            sel = which == k
            n[sel, k] = np.sign(p[sel, k])
    else:
        side = which == 0
        n[side, :2] = p[side, :2] / np.maximum(np.linalg.norm(p[side, :2], axis=1, keepdims=True), 1e-12)
        n[~side, 2] = np.sign(p[~side, 2])
    return t, n @ R.T


def _rays_near(obj: SceneObject, T_map_camera: np.ndarray, K: CameraIntrinsics) -> np.ndarray:
    """Indices (row-major) of the pixels inside the image rectangle around the projection
    of ``obj``'s bounding box (all pixels when a corner is not in front of the camera)."""
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    half = np.asarray(obj.size, float) / 2.0
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    pts = corners @ R.T + np.asarray(obj.centre, float)
    cam = (pts - T_map_camera[:3, 3]) @ T_map_camera[:3, :3]
    if np.any(cam[:, 2] <= 1e-6):
        return np.arange(K.width * K.height)
    u = K.fx * cam[:, 0] / cam[:, 2] + K.cx
    v = K.fy * cam[:, 1] / cam[:, 2] + K.cy
    x0, x1 = max(int(np.floor(u.min())) - 1, 0), min(int(np.ceil(u.max())) + 1, K.width - 1)
    y0, y1 = max(int(np.floor(v.min())) - 1, 0), min(int(np.ceil(v.max())) + 1, K.height - 1)
    if x1 < x0 or y1 < y0:
        return np.zeros(0, np.int64)
    ys, xs = np.mgrid[y0 : y1 + 1, x0 : x1 + 1]
    return (ys * K.width + xs).ravel()


def render_scene(
    objects: list[SceneObject] | tuple[SceneObject, ...],
    T_map_camera: np.ndarray,
    intrinsics: CameraIntrinsics,
    *,
    support_z: float | None = 0.0,
    support_colour: tuple[int, int, int] = (150, 130, 105),
    max_depth: float = 6.0,
) -> RenderedView:
    """The exact RGB-D view of ``objects`` standing on the plane ``z = support_z`` (None:
    no plane) from the camera at ``T_map_camera``. Hits beyond ``max_depth`` [m] are
    background. Shading: ambient plus Lambertian from a fixed light."""
    K = intrinsics
    H, W = K.height, K.width
    us, vs = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    rays_cam = np.stack([(us - K.cx) / K.fx, (vs - K.cy) / K.fy, np.ones_like(us)], axis=-1).reshape(-1, 3)
    T = np.asarray(T_map_camera, float)
    dirs = rays_cam @ T[:3, :3].T
    origin = T[:3, 3]
    best = np.full(len(dirs), np.inf)
    labels = np.full(len(dirs), BACKGROUND, dtype=np.int32)
    normals = np.zeros_like(dirs)
    if support_z is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (support_z - origin[2]) / dirs[:, 2]
        ok = np.isfinite(t) & (t > 0)
        best[ok] = t[ok]
        labels[ok] = SUPPORT
        normals[ok] = (0.0, 0.0, 1.0)
    for i, obj in enumerate(objects):
        rays = _rays_near(obj, T, K)
        t, n = _hit(obj, origin, dirs[rays])
        nearer = t < best[rays]
        idx = rays[nearer]
        best[idx], labels[idx], normals[idx] = t[nearer], i, n[nearer]
    far = best > max_depth
    best[far], labels[far] = np.nan, BACKGROUND
    colours = np.array([support_colour, *[o.colour for o in objects], (70, 80, 95)], dtype=float)
    base = colours[np.where(labels == SUPPORT, 0, np.where(labels == BACKGROUND, len(colours) - 1, labels + 1))]
    shade = np.where(labels == BACKGROUND, 1.0, 0.45 + 0.55 * np.clip(normals @ _LIGHT, 0.0, 1.0))
    rgb = np.clip(base * shade[:, None], 0, 255).astype(np.uint8).reshape(H, W, 3)
    return RenderedView(rgb, best.astype(np.float32).reshape(H, W), labels.reshape(H, W))


def object_box(labels: np.ndarray, index: int) -> tuple[int, int, int, int] | None:
    """The axis-aligned box ``(x, y, w, h)`` [px] of the pixels labelled ``index`` (what a
    perfect detector returns), or None when none is visible."""
    ys, xs = np.nonzero(labels == index)
    if len(xs) == 0:
        return None
    return int(xs.min()), int(ys.min()), int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)


def spoil_depth(
    depth: np.ndarray,
    rng: np.random.Generator,
    *,
    noise_per_metre: float = 0.002,
    holes: float = 0.05,
    hole_blobs: int = 3,
    hole_radius_px: tuple[int, int] = (2, 8),
    flying: float = 0.5,
    edge_jump: float = 0.03,
) -> np.ndarray:
    """``depth`` [m] spoilt like a stereo depth camera's:

    * noise with sigma ``noise_per_metre * z`` [m] (2 mm at 1 m by default), half of the
      variance white, half blurred over about 3 px (stereo matching windows);
    * ``hole_blobs`` round holes of a radius drawn from ``hole_radius_px`` at random
      valid pixels, then scattered holes until ``holes`` of the valid pixels are nan;
    * mixed pixels: each pixel next to a depth jump over ``edge_jump`` [m] takes, with
      probability ``flying``, a depth between its own and its far neighbour's.

    Returns a new float32 image."""
    z = np.asarray(depth, dtype=np.float64).copy()
    valid = np.isfinite(z)
    H, W = z.shape
    # mixed pixels at depth edges (before noise, from the true jumps)
    zn = np.where(valid, z, -np.inf)
    farthest = np.max([np.roll(zn, s, axis=a) for a in (0, 1) for s in (1, -1)], axis=0)  # -inf: none valid
    jump = np.where(valid & np.isfinite(farthest), farthest - np.where(valid, z, 0.0), 0.0)
    edge = (jump > edge_jump) & (rng.random(z.shape) < flying)
    w = rng.random(z.shape)
    z = np.where(edge, z + w * jump, z)
    # noise
    sigma = noise_per_metre * np.where(valid, z, 0.0)
    white = rng.standard_normal(z.shape)
    corr = cv2.GaussianBlur(rng.standard_normal(z.shape), (0, 0), 1.5)
    corr /= max(float(corr.std()), 1e-12)
    z = z + sigma * (white + corr) / math.sqrt(2.0)
    # holes
    mask = np.zeros((H, W), np.uint8)
    vy, vx = np.nonzero(valid)
    if len(vx):
        for k in rng.integers(0, len(vx), hole_blobs):
            cv2.circle(mask, (int(vx[k]), int(vy[k])), int(rng.integers(hole_radius_px[0], hole_radius_px[1] + 1)), 1, -1)
        need = int(holes * len(vx)) - int((mask.astype(bool) & valid).sum())
        if need > 0:
            pick = rng.choice(len(vx), size=min(need, len(vx)), replace=False)
            mask[vy[pick], vx[pick]] = 1
    z[mask.astype(bool)] = np.nan
    return z.astype(np.float32)
