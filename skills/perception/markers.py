"""ArUco marker detection and pose, refined with depth and expressed in ``map``.

Frames (see :mod:`mmexec.drivers.interfaces`): the camera optical frame has z forward,
x right, y down. The marker frame is OpenCV's: origin at the centre of the black square,
x right, y up as printed, z out of the printed face (towards a camera that sees it).
Object points for ``solvePnP(..., SOLVEPNP_IPPE_SQUARE)`` are top-left, top-right,
bottom-right, bottom-left: ``(-l/2, l/2, 0), (l/2, l/2, 0), (l/2, -l/2, 0), (-l/2, -l/2, 0)``.

Speed: OpenCV's default detector costs 7-14 ms on a 640x480 frame, mostly in the
adaptive thresholding at three window sizes over the whole image. :class:`MarkerDetector`
instead (1) looks in a region of interest around the markers it found last time, (2)
searches the whole image downscaled 2x with a single threshold window, and (3) always
refines the corners at full resolution with ``cv2.cornerSubPix``, so the accuracy is the
full-resolution one. If the wanted markers are still missing it can fall back to the
full-resolution detector (``fallback_full``).

The region-of-interest pass only replaces the whole-image pass when it already found
everything the caller asked for (``detect(image, want={7})`` and marker 7 is in the ROI):
a marker that came into view since the last frame (the camera turned) is never missed.
Without ``want``, the whole image is searched at least every ``full_every`` frames
(default: every frame).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Collection
from dataclasses import dataclass

import cv2
import numpy as np

from mmexec.drivers.interfaces import CameraFrame, CameraIntrinsics

__all__ = [
    "DetectorConfig",
    "MarkerDetection",
    "MarkerDetector",
    "MarkerObservation",
    "depth_plane_normal",
    "estimate_marker_pose",
    "marker_object_points",
    "marker_pose_candidates",
    "observe_markers",
    "refine_pose_with_depth",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DetectorConfig:
    """Detection settings. ``dictionary`` is a ``cv2.aruco`` predefined dictionary name;
    ``marker_length`` [m] is the side of the black square; ``downscale`` the factor of the
    fast first pass (1 = full resolution); ``roi_margin`` [fraction of the marker size]
    around the previous detection searched first; ``threshold_window`` [px, odd, at the
    detection scale] the single adaptive-threshold window of the fast pass;
    ``full_every`` [frames]: when the caller names no wanted ids, the whole image is
    searched at least once every this many frames (1: every frame; larger values trade
    the latency of spotting a newly visible marker for speed)."""

    dictionary: str = "DICT_4X4_50"
    marker_length: float = 0.05
    downscale: int = 2
    use_roi: bool = True
    roi_margin: float = 0.6
    full_every: int = 1
    threshold_window: int = 7
    fallback_full: bool = True
    subpix_window: int = 5
    min_marker_perimeter_px: float = 40.0   # at full resolution
    depth_refine: bool = True
    depth_min_fraction: float = 0.3          # fraction of quad pixels with valid depth
    depth_range: tuple[float, float] = (0.1, 10.0)  # m

    def validate(self) -> list[str]:
        errs = []
        if not hasattr(cv2.aruco, self.dictionary) or not self.dictionary.startswith("DICT_"):
            errs.append(f"dictionary: unknown ArUco dictionary {self.dictionary!r}")
        if not self.marker_length > 0:
            errs.append(f"marker_length: must be > 0 m, got {self.marker_length}")
        if self.downscale < 1:
            errs.append(f"downscale: must be >= 1, got {self.downscale}")
        if self.threshold_window < 3 or self.threshold_window % 2 == 0:
            errs.append(f"threshold_window: must be odd and >= 3, got {self.threshold_window}")
        if self.full_every < 1:
            errs.append(f"full_every: must be >= 1 frame, got {self.full_every}")
        return errs


@dataclass(frozen=True)
class MarkerDetection:
    """A marker found in an image: ``corners`` 4x2 float32 pixels (TL, TR, BR, BL)."""

    id: int
    corners: np.ndarray


@dataclass(frozen=True)
class MarkerObservation:
    """One marker seen in one frame.

    ``T_map_marker`` and ``T_camera_marker``: 4x4 marker pose in ``map`` and in the camera
    optical frame; ``corners`` 4x2 pixels (TL, TR, BR, BL); ``reprojection_error`` RMS
    [px]; ``distance`` [m] camera to marker centre; ``stamp`` [s, clock time of the
    frame]; ``depth_refined`` tells whether the depth image corrected the translation.
    """

    id: int
    T_map_marker: np.ndarray
    T_camera_marker: np.ndarray
    corners: np.ndarray
    reprojection_error: float
    distance: float
    stamp: float
    depth_refined: bool = False


def marker_object_points(length: float) -> np.ndarray:
    """4x3 object points (TL, TR, BR, BL) of a marker of side ``length`` [m]."""
    h = length / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]], dtype=np.float64)


def estimate_marker_pose(
    corners: np.ndarray, intrinsics: CameraIntrinsics, length: float
) -> tuple[np.ndarray, float]:
    """``(T_camera_marker, rms_reprojection_error_px)`` from the 4 corner pixels with
    ``SOLVEPNP_IPPE_SQUARE`` (the solution with the smaller reprojection error)."""
    sols = marker_pose_candidates(corners, intrinsics, length)
    return sols[0]


def marker_pose_candidates(
    corners: np.ndarray, intrinsics: CameraIntrinsics, length: float
) -> list[tuple[np.ndarray, float]]:
    """Both IPPE solutions ``(T_camera_marker, rms_px)``, best reprojection first. A small
    or far marker seen nearly head-on has two poses mirrored about the line of sight with
    similar errors (the planar-pose ambiguity); depth can tell them apart. When IPPE fails
    (no finite solution, or none within 0.5 px) SQPnP's solution is added."""
    K = intrinsics.matrix()
    dist = np.asarray(intrinsics.dist, dtype=np.float64)
    obj = marker_object_points(length)
    img = np.asarray(corners, dtype=np.float64).reshape(4, 1, 2)
    out = _pnp(obj, img, K, dist, cv2.SOLVEPNP_IPPE_SQUARE)
    if not out or min(e for _, e in out) > 0.5:
        # IPPE_SQUARE degenerates for a square seen exactly fronto-parallel (NaN, or a
        # pose tilted by degrees with a sub-pixel-looking error): add SQPnP's solution
        out += _pnp(obj, img, K, dist, cv2.SOLVEPNP_SQPNP)
    if not out:
        raise ValueError("solvePnP failed on the marker corners")
    out.sort(key=lambda x: x[1])
    return out


def _pnp(obj: np.ndarray, img: np.ndarray, K: np.ndarray, dist: np.ndarray, flag: int) -> list[tuple[np.ndarray, float]]:
    """Finite solutions ``(T_camera_marker, rms_px)`` of ``solvePnPGeneric`` with ``flag``."""
    try:
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, K, dist, flags=flag)
    except cv2.error as e:
        log.debug("solvePnP (flag %d) failed: %s", flag, e)
        return []
    out = []
    for rvec, tvec in list(zip(rvecs, tvecs))[: n or 0]:
        if not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
            continue
        R, _ = cv2.Rodrigues(rvec)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = np.asarray(tvec).ravel()
        proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
        err = float(np.sqrt(np.mean(np.sum((proj.reshape(4, 2) - img.reshape(4, 2)) ** 2, axis=1))))
        out.append((T, err))
    return out


def depth_plane_normal(
    corners: np.ndarray, depth: np.ndarray, intrinsics: CameraIntrinsics, *, min_points: int = 30
) -> np.ndarray | None:
    """Unit normal (camera frame, pointing towards the camera) of the plane fitted by SVD to
    the depth points inside the marker quad, or None with too few valid depths."""
    quad = np.asarray(corners, dtype=np.float64).reshape(4, 2)
    c = quad.mean(axis=0)
    inner = c + 0.9 * (quad - c)
    h, w = depth.shape[:2]
    x0, y0 = np.maximum(np.floor(inner.min(axis=0)).astype(int), 0)
    x1, y1 = np.minimum(np.ceil(inner.max(axis=0)).astype(int), (w - 1, h - 1))
    if x1 <= x0 or y1 <= y0:
        return None
    mask = np.zeros((y1 - y0 + 1, x1 - x0 + 1), np.uint8)
    cv2.fillConvexPoly(mask, np.round(inner - (x0, y0)).astype(np.int32), 1)
    patch = depth[y0 : y1 + 1, x0 : x1 + 1]
    ok = (mask > 0) & np.isfinite(patch) & (patch > 0)
    if int(ok.sum()) < min_points:
        return None
    vs, us = np.nonzero(ok)
    z = patch[ok].astype(np.float64)
    X = (us + x0 - intrinsics.cx) / intrinsics.fx * z
    Y = (vs + y0 - intrinsics.cy) / intrinsics.fy * z
    P = np.stack([X, Y, z], axis=1)
    _, _, Vt = np.linalg.svd(P - P.mean(axis=0), full_matrices=False)
    nrm = Vt[2]
    if nrm[2] > 0:  # towards the camera: negative optical z
        nrm = -nrm
    return nrm


def refine_pose_with_depth(
    T_camera_marker: np.ndarray,
    corners: np.ndarray,
    depth: np.ndarray,
    *,
    min_fraction: float = 0.3,
    depth_range: tuple[float, float] = (0.1, 10.0),
) -> tuple[np.ndarray, bool]:
    """Correct the translation's scale with the depth image.

    The marker is planar, so the depth at its centre pixel is the z of its centre in the
    camera frame. The median of the valid depths inside the marker quad (robust to holes
    and edge pixels) is compared with the z of the PnP translation; the translation is
    scaled along its ray so its z equals that median. The rotation is kept (PnP gets it
    right from the corner geometry; the scale is what a wrong marker size or a poor
    focal length spoils). Returns ``(T, refined)``; ``refined`` is False when too few
    depth pixels are valid (then ``T`` is returned unchanged).
    """
    h, w = depth.shape[:2]
    quad = np.asarray(corners, dtype=np.float64).reshape(4, 2)
    # shrink the quad towards its centre to stay clear of edge pixels
    c = quad.mean(axis=0)
    inner = c + 0.7 * (quad - c)
    x0, y0 = np.floor(inner.min(axis=0)).astype(int)
    x1, y1 = np.ceil(inner.max(axis=0)).astype(int)
    x0, y0 = max(x0, 0), max(y0, 0)
    x1, y1 = min(x1, w - 1), min(y1, h - 1)
    if x1 <= x0 or y1 <= y0:
        return T_camera_marker, False
    mask = np.zeros((y1 - y0 + 1, x1 - x0 + 1), np.uint8)
    cv2.fillConvexPoly(mask, np.round(inner - (x0, y0)).astype(np.int32), 1)
    patch = depth[y0 : y1 + 1, x0 : x1 + 1]
    vals = patch[(mask > 0) & np.isfinite(patch)]
    vals = vals[(vals > depth_range[0]) & (vals < depth_range[1])]
    total = int(mask.sum())
    if total == 0 or len(vals) < max(4, min_fraction * total):
        return T_camera_marker, False
    z_depth = float(np.median(vals))
    t = T_camera_marker[:3, 3]
    if t[2] <= 0:
        return T_camera_marker, False
    T = T_camera_marker.copy()
    T[:3, 3] = t * (z_depth / t[2])
    return T, True


class MarkerDetector:
    """Fast ArUco detector (see the module doc). Stateful: it remembers where markers were
    in the previous frame to search there first. Not thread-safe."""

    def __init__(self, config: DetectorConfig | None = None) -> None:
        self.config = config or DetectorConfig()
        errs = self.config.validate()
        if errs:
            raise ValueError("DetectorConfig: " + "; ".join(errs))
        cfg = self.config
        self._dict = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, cfg.dictionary))
        fast = cv2.aruco.DetectorParameters()
        fast.adaptiveThreshWinSizeMin = cfg.threshold_window
        fast.adaptiveThreshWinSizeMax = cfg.threshold_window
        fast.adaptiveThreshWinSizeStep = 10
        fast.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
        self._fast = cv2.aruco.ArucoDetector(self._dict, fast)
        full = cv2.aruco.DetectorParameters()
        full.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self._full = cv2.aruco.ArucoDetector(self._dict, full)
        self._last: list[tuple[int, int, int, int]] = []  # ROIs x0, y0, x1, y1 (full res)
        self._since_full = 0  # frames since the whole image was last searched
        self.last_method = ""

    def reset(self) -> None:
        """Forget the previous detections: the next frame searches the whole image. Not
        needed when the view changes (see :meth:`detect`); frees the ROI state."""
        self._last = []
        self._since_full = 0

    def _run_fast(self, gray: np.ndarray, scale: int) -> list[MarkerDetection]:
        img = gray
        if scale > 1:
            img = cv2.resize(gray, (gray.shape[1] // scale, gray.shape[0] // scale), interpolation=cv2.INTER_AREA)
        corners, ids, _ = self._fast.detectMarkers(img)
        if ids is None or len(ids) == 0:
            return []
        out = []
        for cid, c in zip(np.asarray(ids).ravel(), corners):
            pts = c.reshape(4, 2).astype(np.float32)
            if scale > 1:
                pts = (pts + 0.5) * scale - 0.5
            out.append(MarkerDetection(int(cid), pts))
        return out

    def _refine(self, gray: np.ndarray, dets: list[MarkerDetection]) -> list[MarkerDetection]:
        win = self.config.subpix_window
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
        out = []
        for d in dets:
            side = float(np.min(np.linalg.norm(d.corners - np.roll(d.corners, 1, axis=0), axis=1)))
            wsz = int(max(2, min(win, side / 4)))
            pts = d.corners.reshape(-1, 1, 2).copy()
            cv2.cornerSubPix(gray, pts, (wsz, wsz), (-1, -1), crit)
            out.append(MarkerDetection(d.id, pts.reshape(4, 2)))
        return out

    def detect(self, gray: np.ndarray, want: Collection[int] | None = None) -> list[MarkerDetection]:
        """Markers in a grey (HxW uint8) or RGB image, corners at full resolution [px].

        ``want``: the marker ids the caller needs. The region-of-interest pass around the
        previous detections stands in for the whole-image pass only when it found every
        wanted id; otherwise (and, without ``want``, at least every ``full_every`` frames)
        the downscaled whole image is searched too and its new markers are added, so a
        marker newly in view is found in the first frame that shows it. When wanted ids
        (or, without ``want``, any marker) are still missing, the full-resolution detector
        runs if ``fallback_full``. All markers found are returned, wanted or not.
        ``last_method`` names the passes that found something (``roi``, ``downscaled``,
        ``full``, joined by ``+``) or ``none``.
        """
        if gray.ndim == 3:
            gray = cv2.cvtColor(gray, cv2.COLOR_RGB2GRAY)
        cfg = self.config
        H, W = gray.shape
        wanted = set(want) if want is not None else None
        full_due = wanted is None and self._since_full + 1 >= cfg.full_every
        fast: list[MarkerDetection] = []   # corners still to refine
        methods: list[str] = []
        if cfg.use_roi and self._last and not full_due:
            for x0, y0, x1, y1 in self._last:
                roi = gray[y0:y1, x0:x1]
                scale = cfg.downscale if min(roi.shape) >= 80 * cfg.downscale else 1
                for d in self._run_fast(roi, scale):
                    _add_new(fast, MarkerDetection(d.id, d.corners + np.array([x0, y0], np.float32)))
            if fast:
                methods.append("roi")
        found_ids = {d.id for d in fast}
        if not fast or full_due or (wanted is not None and not wanted <= found_ids):
            self._since_full = 0
            before = len(fast)
            for d in self._run_fast(gray, cfg.downscale):
                _add_new(fast, d)
            if len(fast) > before:
                methods.append("downscaled")
        else:
            self._since_full += 1
        dets = self._refine(gray, fast) if fast else []
        found_ids = {d.id for d in dets}
        missing = (not dets) if wanted is None else not wanted <= found_ids
        if missing and cfg.fallback_full:
            corners, ids, _ = self._full.detectMarkers(gray)
            if ids is not None and len(ids):
                before = len(dets)
                for i, c in zip(np.asarray(ids).ravel(), corners):
                    _add_new(dets, MarkerDetection(int(i), c.reshape(4, 2).astype(np.float32)))
                if len(dets) > before:
                    methods.append("full")
        dets = [d for d in dets if _perimeter(d.corners) >= cfg.min_marker_perimeter_px]
        self.last_method = "+".join(methods) or "none"
        self._last = []
        for d in dets:
            lo, hi = d.corners.min(axis=0), d.corners.max(axis=0)
            m = cfg.roi_margin * float(max(hi - lo))
            self._last.append((
                max(0, int(lo[0] - m)), max(0, int(lo[1] - m)),
                min(W, math.ceil(hi[0] + m) + 1), min(H, math.ceil(hi[1] + m) + 1),
            ))
        return dets


def _add_new(dets: list[MarkerDetection], d: MarkerDetection, tol: float = 4.0) -> None:
    """Append ``d`` unless a detection of the same id lies within ``tol`` px (corner mean)."""
    c = d.corners.mean(axis=0)
    for e in dets:
        if e.id == d.id and float(np.linalg.norm(e.corners.mean(axis=0) - c)) <= tol:
            return
    dets.append(d)


def _perimeter(c: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(c - np.roll(c, 1, axis=0), axis=1)))


def observe_markers(
    frame: CameraFrame,
    detector: MarkerDetector,
    ids: set[int] | None = None,
    *,
    marker_length: float | None = None,
    want: set[int] | None = None,
) -> list[MarkerObservation]:
    """Detect markers in ``frame`` (optionally only ``ids``), estimate each pose, refine it
    with the frame's depth image when there is one, and express it in ``map`` through
    ``T_map_base @ T_base_camera``. ``marker_length`` [m] overrides the detector's.
    ``ids`` are also the detector's wanted ids (see :meth:`MarkerDetector.detect`);
    ``want``: wanted ids when every marker is returned (``ids`` None)."""
    cfg = detector.config
    length = marker_length if marker_length is not None else cfg.marker_length
    dets = detector.detect(frame.rgb, want=ids if ids is not None else want)
    out: list[MarkerObservation] = []
    T_map_cam = np.asarray(frame.T_map_base) @ np.asarray(frame.T_base_camera)
    for d in dets:
        if ids is not None and d.id not in ids:
            continue
        try:
            cands = marker_pose_candidates(d.corners, frame.intrinsics, length)
        except ValueError as e:
            log.warning("marker %d: %s", d.id, e)
            continue
        T_cm, err = cands[0]
        if frame.depth is not None and cfg.depth_refine and len(cands) > 1:
            # resolve the planar ambiguity with the depth plane's normal
            nrm = depth_plane_normal(d.corners, frame.depth, frame.intrinsics)
            if nrm is not None:
                T_cm, err = max(cands, key=lambda c: float(np.dot(c[0][:3, 2], nrm)))
        refined = False
        if cfg.depth_refine and frame.depth is not None:
            T_cm, refined = refine_pose_with_depth(
                T_cm, d.corners, frame.depth, min_fraction=cfg.depth_min_fraction, depth_range=cfg.depth_range
            )
        out.append(
            MarkerObservation(
                id=d.id,
                T_map_marker=T_map_cam @ T_cm,
                T_camera_marker=T_cm,
                corners=d.corners,
                reprojection_error=err,
                distance=float(np.linalg.norm(T_cm[:3, 3])),
                stamp=frame.stamp,
                depth_refined=refined,
            )
        )
    return out

