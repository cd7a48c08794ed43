"""Grasp point of a detected object from its box and the depth image, in ``map``.

The paper (locobot-holistic-planning-dangerous-objects, section III-C) takes the centre of
the detector's box as the object's centre of mass, reads the depth image there and
back-projects that pixel: a point on the object's visible surface, at the camera's pose
(Fig. 3). Its pick (IV-C) reaches a pre-grasp pose "located above the object
(orthogonal to the plane where the item is placed), with the gripper pointing towards
it". For a dangerous item the operator clicks the dangerous part on the last image and
the grasp pixel becomes the mean of the predicted and clicked pixels (IV-E, Fig. 7).

:func:`estimate_grasp` does the paper's steps and then corrects for what they leave out:

1. **Surface point** (the paper's grasp point): the box centre pixel's depth is the
   median of the valid depths in a small window around it (holes, nan or 0, and depths
   outside ``depth_range`` dropped; the window grows up to the box when too few are
   valid), back-projected with the intrinsics and moved to ``map`` through
   ``T_map_base @ T_base_camera``.
2. **Object points**: the pixels inside the box (grown by ``box_grow`` when the item's
   size is known, as a detector's box may cut the item), without mixed pixels (a jump
   over ``edge_jump`` to a neighbour), within the object's extent of the surface depth,
   back-projected to ``map``. Support: the plane ``z = top - height`` when the
   item's size is known (catalogue), else the lowest points; points less than
   ``support_margin`` above it are the support, not the object. The support plane is
   horizontal in ``map`` (z up): tables, shelf boards, the floor.
3. **Footprint**: the minimum-area rectangle of the object points seen from above
   (``cv2.minAreaRect``), its extents trimmed of the outermost ``trim`` of the points.
   A camera that sees an item only from the front sees only its near side: with the
   item's size known, each side shorter than the catalogue's is completed away from the
   camera (the hidden part is behind), so the centre is the near edge plus half the
   true side, in proportion to how much that side faces the camera. An upright
   cylinder's visible arc completes the same way.
4. **Centre of mass**: the footprint's centre at half the height between support and top
   (a uniform solid), the figure ``benchmarks/detection.py`` measures against the truth.
5. **Orientation**, from the object's box (the footprint rectangle and the height), not
   the image box (whose long side mixes depth and height when the camera looks down):
   the top grasp closes the fingers across the footprint's short side (a near-square
   footprint: across the side facing the camera); the front grasp approaches
   horizontally from the camera's side and closes across the smaller of the visible
   width and the height.

Grasp frames follow the marker convention of :mod:`mmexec.skills.manipulation.grasp`
(z out of the "face" towards where the gripper comes from, x the fingers' travel, y the
tool's up), so :func:`~mmexec.skills.manipulation.grasp.grasp_poses` turns them into
pre-grasp, grasp and retract tool poses: ``T_map_top`` has z up, so
``grasp_poses(T_map_top, axis, pre_grasp=(0, 0, 0.1), retract=(0, 0, 0.1))`` puts the
pre-grasp 10 cm above the object, orthogonal to the support plane, and retracts straight
up; ``T_map_front`` has z horizontal towards the camera (the seed's front grasp). Both
frames' origin is the centre of mass.

:func:`correct_grasp_pixel` is the dangerous-object correction (mean of the predicted
and clicked pixels, logged with both); :func:`move_grasp` moves a grasp to the corrected
pixel.

Units: metres, radians, pixels; ``map`` z up. Depth is along the optical z axis.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from mmexec.drivers.interfaces import CameraFrame, CameraIntrinsics

__all__ = [
    "GraspPoint",
    "GraspPointConfig",
    "GraspPointError",
    "PixelCorrection",
    "back_project",
    "correct_grasp_pixel",
    "estimate_grasp",
    "move_grasp",
    "pixel_depth",
]

log = logging.getLogger(__name__)

Box = tuple[int, int, int, int]


class GraspPointError(ValueError):
    """No grasp point from this box and depth image (no valid depth, too few points)."""


@dataclass(frozen=True)
class GraspPointConfig:
    """Settings of :func:`estimate_grasp`.

    ``centre_window``: side of the window around the grasp pixel whose median depth is
    taken, as a fraction of the box's sides (at least 3 px). ``min_valid``: valid depths
    the window needs (it doubles, up to the whole box, until it has them).
    ``depth_range`` [m]: depths outside are holes. ``box_grow``: fraction of the box's
    sides added at each edge before taking object points, for a detector's box that cuts
    the object, when the item's size is known (the support plane then comes from the
    object's top and drops what the growth adds; without the size, the lowest points
    would be the grown box's surroundings, so the box is taken as given); negative
    values remove a margin in both cases. ``edge_jump`` [m]: a pixel
    whose depth differs from a 4-neighbour's by more is a mixed pixel and dropped.
    ``support_margin`` [m]: points less high above the support are the support.
    ``min_points``: fewer object points is no grasp. ``trim``: fraction of the points
    left outside the footprint at each end of each side (flying pixels).
    ``square_tolerance``: footprints whose sides differ by less than this fraction of
    the long side are square (the fingers close across the side facing the camera)."""

    centre_window: float = 0.2
    min_valid: int = 5
    depth_range: tuple[float, float] = (0.1, 5.0)
    box_grow: float = 0.1
    edge_jump: float = 0.02
    support_margin: float = 0.01
    min_points: int = 30
    trim: float = 0.01
    square_tolerance: float = 0.15

    def validate(self) -> list[str]:
        """Problems with the settings (empty when usable)."""
        errs = []
        if not 0 < self.centre_window <= 1:
            errs.append(f"centre_window: must be in (0, 1], got {self.centre_window}")
        if self.min_valid < 1 or self.min_points < 3:
            errs.append(f"min_valid, min_points: must be >= 1 and >= 3, got {self.min_valid}, {self.min_points}")
        if not 0 < self.depth_range[0] < self.depth_range[1]:
            errs.append(f"depth_range: must be 0 < near < far m, got {self.depth_range}")
        if not -0.5 < self.box_grow <= 1.0:
            errs.append(f"box_grow: must be in (-0.5, 1], got {self.box_grow}")
        if not 0 <= self.trim < 0.5:
            errs.append(f"trim: must be in [0, 0.5), got {self.trim}")
        if not (self.edge_jump > 0 and self.support_margin >= 0 and self.square_tolerance >= 0):
            errs.append("edge_jump must be > 0 m, support_margin >= 0 m, square_tolerance >= 0")
        return errs


@dataclass(frozen=True)
class GraspPoint:
    """A grasp point and the object estimate behind it (``map``, metres, radians).

    ``pixel`` ``(u, v)`` [px]: the grasp pixel (the box centre, or a corrected pixel);
    ``depth`` [m]: its robust depth; ``surface`` (3,): that pixel back-projected at that
    depth (the paper's grasp point); ``centre`` (3,): the estimated centre of mass;
    ``footprint`` ``(long, short)`` [m] and ``height`` [m] of the object's box;
    ``yaw`` [rad, in (-pi/2, pi/2]]: direction of the footprint's long side about map z;
    ``support_z`` [m]: height of the support plane; ``view`` (3,): horizontal unit
    vector from the camera towards the object; ``T_map_top`` / ``T_map_front``: 4x4 grasp
    frames (see the module doc); ``top_width`` / ``front_width`` [m]: the object's size
    across the fingers for each grasp; ``points``: object points used."""

    pixel: tuple[float, float]
    depth: float
    surface: np.ndarray
    centre: np.ndarray
    footprint: tuple[float, float]
    height: float
    yaw: float
    support_z: float
    view: np.ndarray
    T_map_top: np.ndarray
    T_map_front: np.ndarray
    top_width: float
    front_width: float
    points: int


def back_project(pixel: tuple[float, float], depth: float, intrinsics: CameraIntrinsics) -> np.ndarray:
    """The point (3,) [m, camera optical frame] at ``depth`` [m along optical z] on the ray
    of ``pixel`` ``(u, v)`` (no lens distortion: registered depth is rectified)."""
    u, v = pixel
    return np.array([(u - intrinsics.cx) / intrinsics.fx * depth, (v - intrinsics.cy) / intrinsics.fy * depth, depth])


def pixel_depth(depth: np.ndarray, pixel: tuple[float, float], half_window: tuple[int, int], *,
                limit: tuple[int, int, int, int] | None = None, depth_range: tuple[float, float] = (0.1, 5.0),
                min_valid: int = 5) -> float:
    """Median of the valid depths [m] in the window of ``half_window`` ``(hx, hy)`` [px]
    around ``pixel``; the window doubles, never past ``limit`` ``(x0, y0, x1, y1)``
    (inclusive; default the image), until it holds ``min_valid`` valid depths (finite,
    inside ``depth_range``). Raises :class:`GraspPointError` when even the largest
    holds none."""
    H, W = depth.shape[:2]
    x0l, y0l, x1l, y1l = limit if limit is not None else (0, 0, W - 1, H - 1)
    u, v = round(pixel[0]), round(pixel[1])
    hx, hy = max(1, half_window[0]), max(1, half_window[1])
    vals = np.zeros(0)
    while True:
        x0, x1 = max(u - hx, x0l, 0), min(u + hx, x1l, W - 1)
        y0, y1 = max(v - hy, y0l, 0), min(v + hy, y1l, H - 1)
        patch = depth[y0 : y1 + 1, x0 : x1 + 1] if x1 >= x0 and y1 >= y0 else np.zeros((0, 0))
        vals = patch[np.isfinite(patch) & (patch > depth_range[0]) & (patch < depth_range[1])]
        whole = x0 <= max(x0l, 0) and y0 <= max(y0l, 0) and x1 >= min(x1l, W - 1) and y1 >= min(y1l, H - 1)
        if len(vals) >= min_valid or whole:
            break
        hx, hy = 2 * hx, 2 * hy
    if len(vals) == 0:
        raise GraspPointError(f"no valid depth around pixel ({pixel[0]:.1f}, {pixel[1]:.1f}) "
                              f"within the box {limit} (holes or outside {depth_range} m)")
    return float(np.median(vals))


def _camera_in_map(frame: CameraFrame) -> np.ndarray:
    return np.asarray(frame.T_map_base, float) @ np.asarray(frame.T_base_camera, float)


def _check_box(box: Box, frame: CameraFrame) -> tuple[int, int, int, int]:
    """The box clipped to the image as inclusive ``(x0, y0, x1, y1)``."""
    if frame.depth is None:
        raise GraspPointError("the camera frame has no depth image")
    H, W = frame.depth.shape[:2]
    x, y, w, h = box
    x0, y0, x1, y1 = max(int(x), 0), max(int(y), 0), min(int(x + w) - 1, W - 1), min(int(y + h) - 1, H - 1)
    if w <= 0 or h <= 0 or x1 < x0 or y1 < y0:
        raise GraspPointError(f"box {tuple(box)} is empty or outside the {W}x{H} image")
    return x0, y0, x1, y1


def _mixed_pixels(depth: np.ndarray, jump: float) -> np.ndarray:
    """HxW bool: pixels whose depth differs from a valid 4-neighbour's by more than
    ``jump`` [m] (mixed pixels across a silhouette)."""
    d = np.where(np.isfinite(depth), depth, np.nan)
    out = np.zeros(d.shape, bool)
    for axis in (0, 1):
        diff = np.abs(np.diff(d, axis=axis)) > jump                       # nan compares False
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        out[tuple(lo)] |= diff
        out[tuple(hi)] |= diff
    return out


def _project(xy: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates (A, N) of points ``xy`` (N, 2) along each angle's first axis
    ``(cos a, sin a)`` and second axis ``(-sin a, cos a)``."""
    c, s = np.cos(angles), np.sin(angles)
    return (np.outer(c, xy[:, 0]) + np.outer(s, xy[:, 1]), np.outer(-s, xy[:, 0]) + np.outer(c, xy[:, 1]))


def _extents(xy: np.ndarray, angles: np.ndarray, trim: float) -> tuple[np.ndarray, np.ndarray]:
    """Trimmed low and high extents (A, 2) of the points ``xy`` along each angle's axes."""
    p1, p2 = _project(xy, angles)
    q1, q2 = np.quantile(p1, [trim, 1.0 - trim], axis=1), np.quantile(p2, [trim, 1.0 - trim], axis=1)
    return np.stack([q1[0], q2[0]], axis=1), np.stack([q1[1], q2[1]], axis=1)


def _edge_cost(xy: np.ndarray, angles: np.ndarray, lo: np.ndarray, hi: np.ndarray, cap: float) -> np.ndarray:
    """Mean distance [m] (each capped at ``cap``) of side points ``xy`` to the nearest
    edge of each angle's rectangle."""
    p1, p2 = _project(xy, angles)
    d = np.minimum(np.minimum(np.abs(p1 - lo[:, :1]), np.abs(p1 - hi[:, :1])),
                   np.minimum(np.abs(p2 - lo[:, 1:]), np.abs(p2 - hi[:, 1:])))
    return np.minimum(d, cap).mean(axis=1)


def _axes(angle: float) -> np.ndarray:
    """(2, 2) rows: the unit axes of a rectangle turned by ``angle`` [rad]."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, s], [-s, c]])


def _footprint(xy: np.ndarray, on_side: np.ndarray, trim: float, max_points: int = 1500
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Axes (2, 2) (rows: unit side directions) and the trimmed low and high extents
    along them of the footprint rectangle of object points ``xy`` (N, 2) [m, map].

    The points on the object's vertical faces (``on_side``) lie on the rectangle's edges,
    which fixes its orientation however few faces are seen (two faces seen from below
    the top are an L, whose minimum-area rectangle is ambiguous: one flush with the
    hypotenuse has the same area): the angle minimises their mean distance to the
    nearest edge, over 0-90 degrees in 2-degree steps, then 0.2-degree steps around the
    best. With fewer than 10 face points (a view from straight above), the
    minimum-area rectangle of all points (``cv2.minAreaRect``)."""
    step = max(1, len(xy) // max_points)
    pts, side = xy[::step], xy[on_side][:: max(1, int(on_side.sum()) // max_points)]
    if len(side) < 10:
        (_, _), (_, _), deg = cv2.minAreaRect(xy.astype(np.float32))
        lo, hi = _extents(xy, np.array([math.radians(deg)]), trim)
        return _axes(math.radians(deg)), lo[0], hi[0]
    coarse = np.radians(np.arange(0.0, 90.0, 2.0))
    lo, hi = _extents(pts, coarse, trim)
    best = float(coarse[int(np.argmin(_edge_cost(side, coarse, lo, hi, 0.01)))])
    fine = best + np.radians(np.arange(-2.0, 2.01, 0.2))
    lo, hi = _extents(pts, fine, trim)
    best = float(fine[int(np.argmin(_edge_cost(side, fine, lo, hi, 0.01)))])
    axes = _axes(best)
    lo, hi = _extents(xy, np.array([best]), trim)
    return axes, *_edges_from_faces(side @ axes.T, lo[0], hi[0], 0.01)


def _edges_from_faces(proj: np.ndarray, lo: np.ndarray, hi: np.ndarray, cap: float) -> tuple[np.ndarray, np.ndarray]:
    """Low and high edges (2,) moved to the median coordinate of the face points ``proj``
    (N, 2, along the rectangle's axes) nearest to each, within ``cap`` [m], where at
    least 10 are (a trimmed extreme of noisy face points lies about two noise sigmas
    outside the face)."""
    edges = np.stack([lo, hi])                                            # (2 ends, 2 axes)
    d = np.abs(proj[:, None, :] - edges[None])                            # (N, end, axis)
    nearest = np.argmin(d.reshape(len(proj), 4), axis=1)
    close = d.reshape(len(proj), 4)[np.arange(len(proj)), nearest] < cap
    out = edges.copy()
    for k in range(4):
        end, axis = divmod(k, 2)
        sel = close & (nearest == k)
        if sel.sum() >= 10:
            out[end, axis] = float(np.median(proj[sel, axis]))
    return out[0], out[1]


def _complete(axes: np.ndarray, lo: np.ndarray, hi: np.ndarray, view: np.ndarray,
              sides: tuple[float, float] | None) -> tuple[np.ndarray, np.ndarray]:
    """The footprint centre (2,) and each axis' side length (2,), completed with the
    known ``sides`` (any order) away from the camera where the measured side is short;
    None: as measured."""
    measured = hi - lo
    centre_local = (lo + hi) / 2.0
    if sides is None:
        return centre_local @ axes, measured
    a, b = sides
    facing = np.clip((axes @ view) / 0.5, -1.0, 1.0)                      # full weight from 60 deg off
    # a side facing the camera may be seen short (its far part is hidden), one across the view may not
    cost = [float(np.sum(np.where(measured > e, 4.0 * (measured - e), (e - measured) * (1.0 - np.abs(facing)))))
            for e in ((a, b), (b, a))]
    expected = np.array((a, b) if cost[0] <= cost[1] else (b, a))
    deficit = np.maximum(expected - measured, 0.0)
    centre_local = centre_local + facing * deficit / 2.0
    return centre_local @ axes, np.maximum(measured, expected)


def _frames(centre: np.ndarray, long_dir: np.ndarray, view: np.ndarray, front_vertical: bool
            ) -> tuple[np.ndarray, np.ndarray]:
    """Top and front grasp frames at ``centre`` (marker convention: x finger travel,
    y tool up, z towards the gripper)."""
    up = np.array([0.0, 0.0, 1.0])
    x = np.array([-long_dir[1], long_dir[0], 0.0])                       # across the long side
    if np.dot(np.cross(up, x)[:2], view) < 0:                             # tool up pointing away from the robot
        x = -x
    top = np.eye(4)
    top[:3, :3] = np.stack([x, np.cross(up, x), up], axis=1)
    top[:3, 3] = centre
    z = np.array([-view[0], -view[1], 0.0])
    y = up
    xf = np.cross(y, z)
    if front_vertical:                                                    # fingers close vertically
        xf, y = up, -np.cross(up, z)
    front = np.eye(4)
    front[:3, :3] = np.stack([xf, y, z], axis=1)
    front[:3, 3] = centre
    return top, front


def estimate_grasp(
    frame: CameraFrame,
    box: Box,
    *,
    size: tuple[float, float, float] | None = None,
    pixel: tuple[float, float] | None = None,
    config: GraspPointConfig | None = None,
) -> GraspPoint:
    """The grasp point of the object in ``box`` ``(x, y, w, h)`` [px] of ``frame`` (see the
    module doc). ``size``: the item's ``(side, side, height)`` [m] from the catalogue,
    which completes a footprint seen from one side; None uses what is seen. ``pixel``:
    the grasp pixel (default: the box centre). Raises :class:`GraspPointError` when the
    depth has no valid value at the pixel or too few object points."""
    cfg = config or GraspPointConfig()
    errs = cfg.validate()
    if errs:
        raise ValueError("GraspPointConfig: " + "; ".join(errs))
    x0, y0, x1, y1 = _check_box(box, frame)
    depth = np.asarray(frame.depth, dtype=np.float64)
    K = frame.intrinsics
    px = pixel if pixel is not None else ((x0 + x1) / 2.0, (y0 + y1) / 2.0)
    half = (max(1, round(cfg.centre_window * (x1 - x0 + 1) / 2)), max(1, round(cfg.centre_window * (y1 - y0 + 1) / 2)))
    z_c = pixel_depth(depth, px, half, limit=(x0, y0, x1, y1), depth_range=cfg.depth_range, min_valid=cfg.min_valid)
    T_mc = _camera_in_map(frame)
    surface = T_mc[:3, :3] @ back_project(px, z_c, K) + T_mc[:3, 3]

    # object points: inside the grown box, no mixed pixels, within the object's extent in depth
    grow = cfg.box_grow if size is not None else min(cfg.box_grow, 0.0)
    mx, my = round(grow * (x1 - x0 + 1)), round(grow * (y1 - y0 + 1))
    H, W = depth.shape[:2]
    bx0, by0, bx1, by1 = max(x0 - mx, 0), max(y0 - my, 0), min(x1 + mx, W - 1), min(y1 + my, H - 1)
    patch = depth[by0 : by1 + 1, bx0 : bx1 + 1]
    reach = math.sqrt(sum(s * s for s in size)) if size is not None else math.hypot(
        (x1 - x0 + 1) * z_c / K.fx, (y1 - y0 + 1) * z_c / K.fy)
    ok = np.isfinite(patch) & (patch > cfg.depth_range[0]) & (patch < cfg.depth_range[1])
    ok &= ~_mixed_pixels(patch, cfg.edge_jump) & (np.abs(patch - z_c) <= reach + 0.02)
    vs, us = np.nonzero(ok)
    zs = patch[vs, us]
    cam = np.stack([(us + bx0 - K.cx) / K.fx * zs, (vs + by0 - K.cy) / K.fy * zs, zs], axis=1)
    pts = cam @ T_mc[:3, :3].T + T_mc[:3, 3]
    if len(pts) < cfg.min_points:
        raise GraspPointError(f"only {len(pts)} valid depth points in the box {tuple(box)} (need {cfg.min_points})")
    top = float(np.quantile(pts[:, 2], 1.0 - cfg.trim))
    support = top - size[2] if size is not None else float(np.quantile(pts[:, 2], cfg.trim))
    obj = pts[(pts[:, 2] > support + cfg.support_margin) & (pts[:, 2] <= top + cfg.support_margin)]
    if len(obj) < cfg.min_points:
        raise GraspPointError(f"only {len(obj)} points above the support at z = {support:.3f} m in the box "
                              f"{tuple(box)} (need {cfg.min_points})")

    cam_xy = T_mc[:2, 3]
    on_side = obj[:, 2] < top - max(cfg.support_margin, 0.1 * (top - support))
    axes, lo, hi = _footprint(obj[:, :2], on_side, cfg.trim)
    view = ((lo + hi) / 2.0) @ axes - cam_xy
    view = view / max(float(np.linalg.norm(view)), 1e-9)
    centre_xy, sides = _complete(axes, lo, hi, view, None if size is None else (size[0], size[1]))
    long_i = int(np.argmax(sides))
    if sides[long_i] - sides[1 - long_i] <= cfg.square_tolerance * sides[long_i]:
        long_i = int(np.argmax(np.abs(axes @ view)))                       # square: fingers across the view
    long_dir = axes[long_i] if axes[long_i] @ np.array([1.0, 0.0]) >= 0 else -axes[long_i]
    height = top - support
    centre = np.array([centre_xy[0], centre_xy[1], (top + support) / 2.0])
    across = np.array([-view[1], view[0]])
    visible_width = float(abs(axes[0] @ across) * sides[0] + abs(axes[1] @ across) * sides[1])
    front_vertical = visible_width > height
    T_top, T_front = _frames(centre, long_dir, view, front_vertical)
    yaw = math.atan2(long_dir[1], long_dir[0])
    if yaw <= -math.pi / 2:
        yaw += math.pi
    elif yaw > math.pi / 2:
        yaw -= math.pi
    return GraspPoint(
        pixel=(float(px[0]), float(px[1])), depth=z_c, surface=surface, centre=centre,
        footprint=(float(sides[long_i]), float(sides[1 - long_i])), height=height, yaw=yaw, support_z=support,
        view=np.array([view[0], view[1], 0.0]), T_map_top=T_top, T_map_front=T_front,
        top_width=float(sides[1 - long_i]), front_width=min(visible_width, height), points=len(obj),
    )


# --------------------------------------------------------------------------- dangerous objects


@dataclass(frozen=True)
class PixelCorrection:
    """The dangerous-object correction (paper IV-E, Fig. 7): the ``predicted`` grasp pixel
    (red), the operator's ``clicked`` pixel on the dangerous part (blue) and the
    ``corrected`` pixel used (green), their mean; ``(u, v)`` [px]."""

    predicted: tuple[float, float]
    clicked: tuple[float, float]
    corrected: tuple[float, float]


def correct_grasp_pixel(predicted: tuple[float, float], clicked: tuple[float, float],
                        image_size: tuple[int, int]) -> PixelCorrection:
    """The grasp pixel moved to the mean of the ``predicted`` one and the operator's
    ``clicked`` one (both ``(u, v)`` [px] in an image of ``image_size`` ``(W, H)``),
    logged with both. Raises ValueError for a click outside the image or not finite."""
    W, H = image_size
    for name, (u, v) in (("predicted", predicted), ("clicked", clicked)):
        if not (math.isfinite(u) and math.isfinite(v) and -0.5 <= u <= W - 0.5 and -0.5 <= v <= H - 0.5):
            raise ValueError(f"{name} pixel ({u}, {v}) is outside the {W}x{H} image")
    mean = ((predicted[0] + clicked[0]) / 2.0, (predicted[1] + clicked[1]) / 2.0)
    out = PixelCorrection((float(predicted[0]), float(predicted[1])), (float(clicked[0]), float(clicked[1])),
                          (float(mean[0]), float(mean[1])))
    log.info("dangerous object: grasp pixel (%.1f, %.1f) and clicked (%.1f, %.1f) -> (%.1f, %.1f)",
             *out.predicted, *out.clicked, *out.corrected)
    return out


def move_grasp(grasp: GraspPoint, frame: CameraFrame, pixel: tuple[float, float], box: Box,
               config: GraspPointConfig | None = None) -> GraspPoint:
    """``grasp`` moved to the grasp pixel ``pixel`` (e.g. :attr:`PixelCorrection.corrected`)
    of the same ``frame`` and object ``box``: the centre moves by the difference of the two
    surface points (the new pixel's robust depth, back-projected), kept between the
    support and the object's top; the orientation is kept. Raises
    :class:`GraspPointError` when the new pixel has no valid depth in the box."""
    cfg = config or GraspPointConfig()
    x0, y0, x1, y1 = _check_box(box, frame)
    half = (max(1, round(cfg.centre_window * (x1 - x0 + 1) / 2)), max(1, round(cfg.centre_window * (y1 - y0 + 1) / 2)))
    z = pixel_depth(np.asarray(frame.depth, dtype=np.float64), pixel, half, limit=(x0, y0, x1, y1),
                    depth_range=cfg.depth_range, min_valid=cfg.min_valid)
    T_mc = _camera_in_map(frame)
    surface = T_mc[:3, :3] @ back_project(pixel, z, frame.intrinsics) + T_mc[:3, 3]
    centre = grasp.centre + (surface - grasp.surface)
    centre[2] = min(max(centre[2], grasp.support_z), grasp.support_z + grasp.height)
    T_top, T_front = grasp.T_map_top.copy(), grasp.T_map_front.copy()
    T_top[:3, 3] = centre
    T_front[:3, 3] = centre
    return replace(grasp, pixel=(float(pixel[0]), float(pixel[1])), depth=z, surface=surface, centre=centre,
                   T_map_top=T_top, T_map_front=T_front)
