"""Fruit perception: detections in the image -> segmented point clouds -> sphere
barycentres in ``map``, scored by the thesis's priority (Algorithms 1.2 and 1.3), and
the operator's click -> barycentre (DemoV1).

:func:`estimate_fruit` runs, per detection of an :class:`~mmexec.skills.perception.detector.ObjectDetector`:

1. the colour mask of its class inside its box grown by :data:`BOX_GROW` of each side
   (the detector's box may cut a partly hidden fruit; a detector with no colours
   (a learned one) gives the box itself, and the fit's outlier model does the rest);
2. the masked depth pixels back-projected to the camera optical frame, holes and
   points at ``z >= max_depth`` dropped (:func:`~mmexec.skills.perception.sphere.depth_to_points`);
3. ``z``: the depth of the points' centroid, the thesis's distance for the priority;
4. the MLESAC sphere fit with the radius range and least-squares refinement
   (:func:`~mmexec.skills.perception.sphere.fit_sphere`): its centre is the barycentre;
5. ``s = c/4 + 3/4 (z_max - z)/z_max`` (:func:`~mmexec.skills.perception.priority.priority_scores`).

A detection without enough points or without a fit is kept out (logged with the
reason). :func:`click_estimate` is DemoV1's pixel: the depth there (median of a small
window, holes skipped), the surface point on the camera ray, and the barycentre one
fitted radius further along the ray; when the points round the click (of the clicked
pixel's colour, at a depth near it) fit a sphere whose surface holds the clicked point,
that fit's centre is taken instead (an off-centre click's ray does not pass through the
centre).

Frames: points and ``centre_camera`` in the camera optical frame (x right, y down, z
forward); ``centre`` in ``map`` through the frame's ``T_map_base @ T_base_camera``. m.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.interfaces import CameraFrame
from mmexec.skills.perception.detector import ColourClass, Detection, ObjectDetector, colour_mask
from mmexec.skills.perception.grasp_point import GraspPointError, back_project, pixel_depth
from mmexec.skills.perception.priority import centroid_depth, priority_scores
from mmexec.skills.perception.sphere import SphereFitConfig, depth_to_points, fit_sphere

__all__ = ["BOX_GROW", "FruitEstimate", "PerceptionSettings", "click_estimate", "estimate_fruit", "merge_estimates"]

log = logging.getLogger(__name__)

#: fraction of the box's sides added at each edge before masking (a cut box)
BOX_GROW = 0.2

Box = tuple[int, int, int, int]


@dataclass(frozen=True)
class PerceptionSettings:
    """``max_depth`` [m] (z_max of the priority and the depth cut), ``radius_range`` [m]
    of the fit, ``min_confidence`` of a detection, ``min_height`` [m] of a barycentre in
    map (lower: on the floor)."""

    max_depth: float = 1.5
    radius_range: tuple[float, float] = (0.025, 0.055)
    min_confidence: float = 0.5
    min_height: float = 0.3


@dataclass(frozen=True)
class FruitEstimate:
    """One fruit: ``label`` and ``confidence`` of its detection, ``box`` [px], barycentre
    ``centre`` [m, map] and ``centre_camera`` [m, optical frame], fitted ``radius`` [m],
    ``z`` the centroid depth [m] of its points, ``score`` (Algorithm 1.3), ``points`` in
    the fit and its ``inlier_fraction``."""

    label: str
    confidence: float
    box: Box
    centre: np.ndarray
    centre_camera: np.ndarray
    radius: float
    z: float
    score: float
    points: int
    inlier_fraction: float

    def to_json(self) -> dict[str, object]:
        return {"label": self.label, "confidence": round(self.confidence, 4), "box": list(self.box),
                "centre": [round(float(v), 4) for v in self.centre], "radius": round(self.radius, 4),
                "z": round(self.z, 4), "score": round(self.score, 4), "points": self.points}


def _grow(box: Box, frac: float, shape: tuple[int, ...]) -> Box:
    x, y, w, h = box
    dx, dy = round(w * frac), round(h * frac)
    x0, y0 = max(0, x - dx), max(0, y - dy)
    x1, y1 = min(shape[1], x + w + dx), min(shape[0], y + h + dy)
    return (x0, y0, x1 - x0, y1 - y0)


def _camera_to_map(frame: CameraFrame, p: np.ndarray) -> np.ndarray:
    T = np.asarray(frame.T_map_base, dtype=float) @ np.asarray(frame.T_base_camera, dtype=float)
    return T[:3, :3] @ p + T[:3, 3]


def _fit(points: np.ndarray, settings: PerceptionSettings, rng: np.random.Generator):
    cfg = SphereFitConfig(radius_range=tuple(settings.radius_range))  # type: ignore[arg-type]
    return fit_sphere(points, cfg, rng)


def estimate_fruit(frame: CameraFrame, detector: ObjectDetector, settings: PerceptionSettings,
                   rng: np.random.Generator) -> list[FruitEstimate]:
    """The fruit in ``frame`` (module docstring), in detection order."""
    colours: Mapping[str, ColourClass] = getattr(detector, "colours", {})
    out: list[FruitEstimate] = []
    dets: Sequence[Detection] = detector.detect(frame.rgb)
    depth = np.asarray(frame.depth, dtype=np.float32)
    for det in dets:
        if det.confidence < settings.min_confidence:
            continue
        box = _grow(det.box, BOX_GROW, depth.shape)
        cls = colours.get(det.label)
        if cls is not None:
            mask = colour_mask(frame.rgb, cls, box)
            pts = depth_to_points(depth, frame.intrinsics, mask=mask, max_depth=settings.max_depth)
        else:
            pts = depth_to_points(depth, frame.intrinsics, box=det.box, max_depth=settings.max_depth)
        if len(pts) < 12:
            log.debug("fruit %s at %s: %d points", det.label, det.box, len(pts))
            continue
        z = centroid_depth(pts)
        fit = _fit(pts, settings, rng)
        if fit is None:
            log.debug("fruit %s at %s: no sphere fit on %d points", det.label, det.box, len(pts))
            continue
        centre = _camera_to_map(frame, fit.centre)
        if centre[2] < settings.min_height:
            continue
        score = float(priority_scores([det.confidence], [z], settings.max_depth)[0])
        out.append(FruitEstimate(det.label, float(det.confidence), det.box, centre, fit.centre.copy(), fit.radius,
                                 float(z), score, len(pts), fit.inlier_fraction))
    return out


def merge_estimates(views: Sequence[Sequence[FruitEstimate]], same: float) -> list[FruitEstimate]:
    """One estimate per fruit over several frames of one view: estimates whose centres
    lie within ``same`` [m] are one fruit, of which the one with the most fitted points
    is kept (ordered by first appearance)."""
    out: list[FruitEstimate] = []
    for view in views:
        for e in view:
            k = next((i for i, o in enumerate(out) if np.linalg.norm(o.centre - e.centre) < same), None)
            if k is None:
                out.append(e)
            elif e.points > out[k].points:
                out[k] = e
    return out


def _like_clicked(rgb: np.ndarray, pixel: tuple[int, int]) -> np.ndarray:
    """HxW bool: pixels of the clicked colour (hue within 10 of the median of the 5x5
    window round ``pixel`` (OpenCV's 0-179 scale), saturation at least half of it); all
    True when the clicked colour is grey (saturation below 60)."""
    import cv2

    hsv = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2HSV).astype(np.int16)
    u, v = pixel
    h, w = hsv.shape[:2]
    patch = hsv[max(0, v - 2):min(h, v + 3), max(0, u - 2):min(w, u + 3)].reshape(-1, 3)
    h0, s0 = int(np.median(patch[:, 0])), int(np.median(patch[:, 1]))
    if s0 < 60:
        return np.ones((h, w), dtype=bool)
    dh = np.abs(hsv[:, :, 0] - h0)
    dh = np.minimum(dh, 180 - dh)
    return (dh <= 10) & (hsv[:, :, 1] >= s0 // 2)


def click_estimate(frame: CameraFrame, pixel: tuple[float, float], settings: PerceptionSettings,
                   rng: np.random.Generator) -> tuple[np.ndarray, float, str]:
    """DemoV1: the barycentre [m, map] of the fruit under ``pixel`` ``(u, v)``, its radius
    [m] and how it was found (``fit`` or ``ray``). Raises :class:`GraspPointError`
    when the pixel has no depth."""
    depth = np.asarray(frame.depth, dtype=np.float32)
    intr = frame.intrinsics
    d0 = pixel_depth(depth, pixel, (2, 2), depth_range=(0.05, settings.max_depth))
    surface = back_project(pixel, d0, intr)
    ray = surface / np.linalg.norm(surface)
    r_max = settings.radius_range[1]
    half = max(3, round(2.0 * r_max * intr.fx / d0))
    u, v = round(pixel[0]), round(pixel[1])
    h, w = depth.shape
    win = np.zeros(depth.shape, dtype=bool)
    win[max(0, v - half):min(h, v + half + 1), max(0, u - half):min(w, u + half + 1)] = True
    near = win & np.isfinite(depth) & (np.abs(depth - d0) < 2.0 * r_max)
    same = near & _like_clicked(frame.rgb, (u, v))
    pts = depth_to_points(depth, intr, mask=same if int(same.sum()) >= 30 else near, max_depth=settings.max_depth)
    fit = _fit(pts, settings, rng) if len(pts) >= 12 else None
    if fit is not None and abs(float(np.linalg.norm(surface - fit.centre)) - fit.radius) < 0.01:
        return _camera_to_map(frame, fit.centre), float(fit.radius), "fit"
    radius = float(fit.radius) if fit is not None else float(np.mean(settings.radius_range))
    return _camera_to_map(frame, surface + radius * ray), radius, "ray"


__all__ += ["GraspPointError"]
