"""Sphere centre (a fruit's or a ball's barycentre) from a segmented depth image.

The thesis (ros2-thesis-follower-buttons-fruit, section 1.3.4, Algorithm 1.2) crops the
depth image to the detector's box, back-projects it to a point cloud, drops points at
``z >= d_max`` (1.5 m), keeps the pixels whose colour matches the predicted class, and
fits a sphere with PCL's ``SACSegmentation`` (MLESAC): minimal samples of 4 points, a
sphere per sample, samples whose radius is outside ``[r_min, r_max]`` discarded, a
maximum-likelihood score over the inliers within ``epsilon``, and a least-squares
refinement of the best model on its inliers. It takes the sphere's centre as the
object's barycentre.

Here the same steps are plain numpy, vectorised over hypotheses:

* :func:`depth_to_points`: depth [m, optical z] + mask + intrinsics -> points in the
  camera optical frame (x right, y down, z forward), holes (nan, 0) and ``z >= max_depth``
  dropped (Algorithm 1.2 lines 3-13; the colour mask is the detector's business, see
  :mod:`.detector`).
* :func:`fit_sphere`: all hypotheses of one fit are solved at once (4-point spheres from
  a 3x3 linear system each), gated by the radius range, and scored by MLESAC (Torr and
  Zisserman 2000): the negative log-likelihood of a mixture of Gaussian inlier residuals
  (``noise_sigma``) and uniform outliers over the point set's extent, the mixing weight
  estimated by a few EM steps per hypothesis. Hypotheses are scored on a random subset
  of at most ``max_points`` points; the refinement uses them all.
* the refinement is Gauss-Newton on the geometric residual ``|p - c| - r`` over the
  inliers (re-selected once after the first refinement). Where we differ from the
  thesis: when the refined radius leaves ``radius_range`` (a small cap of a sphere fixes
  its radius poorly and the centre slides along the view ray with it), the radius is
  clamped to the range and only the centre is refined; PCL's refinement is unconstrained.

The thesis grasps with a soft gripper on an Igus Rebel (MoveIt 2), where a few
millimetres of centre error do not matter; our parallel grippers need the centre within
the finger clearance, which is why the radius clamp and the measurement in
``benchmarks/sphere_fit.py`` exist.

:func:`render_sphere_depth` draws the exact depth image of a sphere (ray/sphere
intersection per pixel of a pinhole camera) and :func:`render_sphere_view` spoils it
(occlusion, noise, holes, outliers) for tests and the benchmark.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np

from mmexec.drivers.interfaces import CameraIntrinsics

__all__ = [
    "SphereFit",
    "SphereFitConfig",
    "SphereView",
    "depth_to_points",
    "fit_sphere",
    "refine_sphere",
    "render_sphere_depth",
    "render_sphere_view",
    "spheres_from_samples",
]

log = logging.getLogger(__name__)

Box = tuple[int, int, int, int]


@dataclass(frozen=True)
class SphereFitConfig:
    """Settings of :func:`fit_sphere`.

    ``radius_range`` [m]: the radii a hypothesis (and the refined fit) may have.
    ``inlier_threshold`` [m]: epsilon, the residual ``||p - c| - r|`` below which a point
    is an inlier. ``noise_sigma`` [m]: the inliers' residual spread in the MLESAC
    likelihood (the depth noise at the working distance). ``iterations``: hypotheses
    drawn. ``max_points``: hypotheses are scored on a random subset of at most this many
    points. ``min_points``: fewer points (or inliers) is no fit. ``min_inlier_fraction``:
    a refined sphere explaining fewer of the points is no fit (a flat patch of a poster
    matches a sphere cap only along a ring). ``em_steps``: EM steps
    estimating the inlier fraction per hypothesis. ``refine_iterations``: Gauss-Newton
    steps per refinement (two refinements: before and after re-selecting the inliers).
    """

    radius_range: tuple[float, float] = (0.025, 0.06)
    inlier_threshold: float = 0.005
    noise_sigma: float = 0.002
    iterations: int = 200
    max_points: int = 600
    min_points: int = 12
    min_inlier_fraction: float = 0.5
    em_steps: int = 3
    refine_iterations: int = 8

    def validate(self) -> list[str]:
        """Problems with the settings (empty when usable)."""
        errs = []
        lo, hi = self.radius_range
        if not 0 < lo <= hi:
            errs.append(f"radius_range: must be 0 < min <= max m, got {self.radius_range}")
        if not self.inlier_threshold > 0:
            errs.append(f"inlier_threshold: must be > 0 m, got {self.inlier_threshold}")
        if not self.noise_sigma > 0:
            errs.append(f"noise_sigma: must be > 0 m, got {self.noise_sigma}")
        if self.iterations < 1:
            errs.append(f"iterations: must be >= 1, got {self.iterations}")
        if self.min_points < 4:
            errs.append(f"min_points: must be >= 4 (a sphere needs 4 points), got {self.min_points}")
        if not 0 <= self.min_inlier_fraction <= 1:
            errs.append(f"min_inlier_fraction: must be in [0, 1], got {self.min_inlier_fraction}")
        if self.max_points < self.min_points:
            errs.append(f"max_points: must be >= min_points ({self.min_points}), got {self.max_points}")
        return errs


@dataclass(frozen=True)
class SphereFit:
    """A fitted sphere in the frame of the input points (the camera optical frame for
    points from :func:`depth_to_points`): ``centre`` (3,) [m], ``radius`` [m],
    ``inliers`` bool (N,) over the input points, ``rms`` [m] residual over the inliers,
    ``cost`` the best hypothesis' MLESAC negative log-likelihood (lower is better),
    ``radius_clamped`` True when the refinement held the radius at a range bound."""

    centre: np.ndarray
    radius: float
    inliers: np.ndarray
    rms: float
    cost: float
    radius_clamped: bool

    @property
    def inlier_fraction(self) -> float:
        return float(np.mean(self.inliers)) if self.inliers.size else 0.0


def depth_to_points(
    depth: np.ndarray,
    intrinsics: CameraIntrinsics,
    *,
    mask: np.ndarray | None = None,
    box: Box | None = None,
    max_depth: float = 1.5,
) -> np.ndarray:
    """(N, 3) points [m] in the camera optical frame from a depth image [m along optical z].

    ``mask`` (HxW bool, same size as ``depth``) keeps only its pixels; ``box``
    ``(x, y, w, h)`` [px] crops first (Algorithm 1.2 lines 3-4). Pixels with no depth (nan,
    inf, <= 0) or with ``z >= max_depth`` are dropped. Lens distortion is ignored (the
    registered depth of an RGB-D camera is rectified)."""
    d = np.asarray(depth)
    x0, y0 = 0, 0
    if box is not None:
        bx, by, bw, bh = box
        x0, y0 = max(int(bx), 0), max(int(by), 0)
        d = d[y0 : max(int(by + bh), y0), x0 : max(int(bx + bw), x0)]
    keep = np.isfinite(d) & (d > 0) & (d < max_depth)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != np.asarray(depth).shape[:2]:
            raise ValueError(f"mask shape {m.shape} differs from depth shape {np.asarray(depth).shape[:2]}")
        keep &= m[y0 : y0 + d.shape[0], x0 : x0 + d.shape[1]]
    vs, us = np.nonzero(keep)
    z = d[vs, us].astype(np.float64)
    x = (us + x0 - intrinsics.cx) / intrinsics.fx * z
    y = (vs + y0 - intrinsics.cy) / intrinsics.fy * z
    return np.stack([x, y, z], axis=1)


def spheres_from_samples(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Spheres through 4 points each: ``samples`` (H, 4, 3) [m] -> centres (H, 3), radii
    (H,) and a bool (H,) that is False for degenerate samples (coplanar or repeated
    points; their centre and radius are nan)."""
    p0 = samples[:, 0, :]
    A = 2.0 * (samples[:, 1:, :] - p0[:, None, :])                      # (H, 3, 3)
    sq = np.einsum("hij,hij->hi", samples, samples)                       # (H, 4)
    b = sq[:, 1:] - sq[:, :1]                                             # (H, 3)
    det = np.linalg.det(A)
    # relative to the sample's spread cubed: coplanar samples are rejected at any scale
    spread = np.max(np.abs(A), axis=(1, 2))
    ok = np.abs(det) > 1e-6 * np.maximum(spread, 1e-12) ** 3
    centres = np.full((len(samples), 3), np.nan)
    if np.any(ok):
        centres[ok] = np.linalg.solve(A[ok], b[ok][:, :, None])[:, :, 0]
    radii = np.linalg.norm(samples[:, 0, :] - centres, axis=1)
    return centres, radii, ok


def _gauss_newton(points: np.ndarray, centre: np.ndarray, radius: float, iterations: int,
                  fixed_radius: bool) -> tuple[np.ndarray, float]:
    """Least squares on ``|p - c| - r`` from (centre, radius); the radius is held when
    ``fixed_radius``."""
    c, r = centre.astype(np.float64).copy(), float(radius)
    for _ in range(iterations):
        diff = points - c
        dist = np.linalg.norm(diff, axis=1)
        dist = np.maximum(dist, 1e-12)
        res = dist - r
        J = -diff / dist[:, None]                                          # d res / d c
        if not fixed_radius:
            J = np.hstack([J, -np.ones((len(points), 1))])                 # d res / d r
        step = np.linalg.lstsq(J, -res, rcond=None)[0]
        c = c + step[:3]
        if not fixed_radius:
            r = r + float(step[3])
        if float(np.max(np.abs(step))) < 1e-7:
            break
    return c, r


def refine_sphere(points: np.ndarray, centre: np.ndarray, radius: float,
                  radius_range: tuple[float, float], iterations: int = 8) -> tuple[np.ndarray, float, bool]:
    """Geometric least-squares refinement of a sphere on ``points`` (N, 3) [m].

    Gauss-Newton on centre and radius; if the radius ends outside ``radius_range`` it is
    clamped to the nearer bound and the centre is refined again with the radius fixed.
    Returns ``(centre, radius, clamped)``."""
    lo, hi = radius_range
    c, r = _gauss_newton(points, centre, radius, iterations, fixed_radius=False)
    if np.all(np.isfinite(c)) and lo <= r <= hi:
        return c, r, False
    r = min(max(r if math.isfinite(r) else radius, lo), hi)
    start = centre if not np.all(np.isfinite(c)) else c
    c, _ = _gauss_newton(points, start, r, iterations, fixed_radius=True)
    return c, r, True


def _mlesac_costs(residuals: np.ndarray, sigma: float, extent: float, em_steps: int) -> np.ndarray:
    """MLESAC negative log-likelihood per hypothesis: ``residuals`` (H, M) [m], inliers
    Gaussian (``sigma``), outliers uniform over ``extent`` [m]; the inlier fraction per
    hypothesis from ``em_steps`` EM steps starting at 0.5."""
    p_in = np.exp(-0.5 * (residuals / sigma) ** 2) / (math.sqrt(2.0 * math.pi) * sigma)
    p_out = 1.0 / extent
    gamma = np.full((residuals.shape[0], 1), 0.5)
    for _ in range(em_steps):
        a = gamma * p_in
        gamma = np.mean(a / (a + (1.0 - gamma) * p_out), axis=1, keepdims=True)
    return -np.sum(np.log(gamma * p_in + (1.0 - gamma) * p_out), axis=1)


def fit_sphere(points: np.ndarray, config: SphereFitConfig, rng: np.random.Generator) -> SphereFit | None:
    """MLESAC sphere fit with a radius range and least-squares refinement (Algorithm 1.2
    lines 14-26) on ``points`` (N, 3) [m, any frame]; None when there are fewer than
    ``min_points`` points, no hypothesis within the radius range, or fewer than
    ``min_points`` inliers or ``min_inlier_fraction`` of the points. Deterministic for a given ``rng`` state."""
    errs = config.validate()
    if errs:
        raise ValueError("SphereFitConfig: " + "; ".join(errs))
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = len(P)
    if n < config.min_points:
        log.debug("sphere fit: %d points, need %d", n, config.min_points)
        return None
    sub = P if n <= config.max_points else P[rng.choice(n, config.max_points, replace=False)]
    idx = rng.integers(0, len(sub), size=(config.iterations, 4))
    centres, radii, ok = spheres_from_samples(sub[idx])
    lo, hi = config.radius_range
    ok &= (radii >= lo) & (radii <= hi)
    if not np.any(ok):
        log.debug("sphere fit: no 4-point sample gives a radius in %s", config.radius_range)
        return None
    centres, radii = centres[ok], radii[ok]
    # |p - c|^2 = |p|^2 - 2 p.c + |c|^2 as one matrix product, about the points' mean
    mean = sub.mean(axis=0)
    q, cq = sub - mean, centres - mean
    d2 = np.einsum("ij,ij->i", q, q)[None, :] - 2.0 * (cq @ q.T) + np.einsum("ij,ij->i", cq, cq)[:, None]
    res = np.abs(np.sqrt(np.maximum(d2, 0.0)) - radii[:, None])
    extent = max(float(np.linalg.norm(np.ptp(sub, axis=0))), 10.0 * config.noise_sigma)
    costs = _mlesac_costs(res, config.noise_sigma, extent, config.em_steps)
    best = int(np.argmin(costs))
    c, r = centres[best], float(radii[best])
    clamped = False
    inl = np.zeros(n, dtype=bool)
    for _ in range(2):  # refine on the inliers, re-select them, refine again
        inl = np.abs(np.linalg.norm(P - c, axis=1) - r) < config.inlier_threshold
        if int(inl.sum()) < config.min_points:
            log.debug("sphere fit: %d inliers, need %d", int(inl.sum()), config.min_points)
            return None
        c, r, clamped = refine_sphere(P[inl], c, r, config.radius_range, config.refine_iterations)
    resid = np.abs(np.linalg.norm(P - c, axis=1) - r)
    inl = resid < config.inlier_threshold
    if int(inl.sum()) < max(config.min_points, config.min_inlier_fraction * n):
        log.debug("sphere fit: %d of %d points are inliers", int(inl.sum()), n)
        return None
    rms = float(np.sqrt(np.mean(resid[inl] ** 2)))
    return SphereFit(centre=c, radius=r, inliers=inl, rms=rms, cost=float(costs[best]), radius_clamped=clamped)


def render_sphere_depth(intrinsics: CameraIntrinsics, centre: np.ndarray, radius: float) -> np.ndarray:
    """Exact depth image [m along optical z] of a sphere seen by a pinhole camera:
    ``centre`` (3,) [m] in the camera optical frame; nan where the ray misses. The ray
    through pixel (u, v) is ``t (x, y, 1)`` with ``x = (u - cx)/fx``, ``y = (v - cy)/fy``,
    so ``t`` of the nearer intersection is the depth."""
    c = np.asarray(centre, dtype=np.float64)
    h, w = intrinsics.height, intrinsics.width
    x = (np.arange(w) - intrinsics.cx) / intrinsics.fx
    y = (np.arange(h) - intrinsics.cy) / intrinsics.fy
    X, Y = np.meshgrid(x, y)
    dd = X * X + Y * Y + 1.0                       # |d|^2
    dc = X * c[0] + Y * c[1] + c[2]                # d . c
    disc = dc * dc - dd * (float(c @ c) - radius * radius)
    with np.errstate(invalid="ignore"):
        t = (dc - np.sqrt(disc)) / dd
    t[(disc < 0) | (t <= 0)] = np.nan
    return t.astype(np.float32)


@dataclass(frozen=True)
class SphereView:
    """A synthetic partial view of a sphere: ``depth`` HxW float32 [m] (nan: no depth),
    ``mask`` HxW bool (the visible part of the sphere's image disc: what a colour mask
    would give, holes and outliers included)."""

    depth: np.ndarray
    mask: np.ndarray


def render_sphere_view(
    intrinsics: CameraIntrinsics,
    centre: np.ndarray,
    radius: float,
    rng: np.random.Generator,
    *,
    visible: float = 1.0,
    noise_per_metre: float = 0.002,
    holes: float = 0.10,
    outliers: float = 0.05,
) -> SphereView:
    """:func:`render_sphere_depth` spoilt the way a stereo depth camera and a plant do.

    * ``visible``: a straight occluding edge (a leaf) at a random angle hides all but this
      fraction of the sphere's image disc;
    * depth noise with sigma ``noise_per_metre`` x depth [m], half of its variance white
      per pixel, half spatially correlated (white noise blurred over about 3 px and
      rescaled), as stereo matching windows correlate neighbouring depths;
    * ``holes`` (fraction of the visible pixels) get no depth: half in one blob around
      the specular spot (the pixel nearest the camera), half scattered;
    * ``outliers`` (fraction) among the rest get a wrong depth: half flying pixels 2-30 cm
      behind the sphere (as on a silhouette against the background), half uniform in
      0.3-1.5 m.
    """
    depth = render_sphere_depth(intrinsics, centre, radius)
    vs, us = np.nonzero(np.isfinite(depth))
    if len(vs) == 0:
        raise ValueError(f"the sphere at {np.asarray(centre).tolist()} m is not in the image")
    ang = rng.uniform(0.0, 2.0 * math.pi)
    proj = us * math.cos(ang) + vs * math.sin(ang)
    keep = proj <= np.quantile(proj, visible)
    vs, us = vs[keep], us[keep]
    z = depth[vs, us].astype(np.float64)
    field = cv2.GaussianBlur(rng.normal(0.0, 1.0, depth.shape), (0, 0), 3.0)
    field /= max(float(field.std()), 1e-12)
    z += noise_per_metre * z * (rng.normal(0.0, 1.0, len(z)) + field[vs, us]) / math.sqrt(2.0)
    n = len(z)
    near = int(np.argmin(depth[vs, us]))
    d2 = (vs - vs[near]) ** 2 + (us - us[near]) ** 2
    hole = np.zeros(n, dtype=bool)
    hole[np.argsort(d2)[: int(0.5 * holes * n)]] = True
    hole[rng.choice(np.flatnonzero(~hole), int(0.5 * holes * n), replace=False)] = True
    bad = rng.choice(np.flatnonzero(~hole), int(outliers * n), replace=False)
    half = len(bad) // 2
    z[bad[:half]] += rng.uniform(0.02, 0.30, half)
    z[bad[half:]] = rng.uniform(0.3, 1.5, len(bad) - half)
    z[hole] = np.nan
    out = np.full(depth.shape, np.nan, dtype=np.float32)
    out[vs, us] = z
    mask = np.zeros(depth.shape, dtype=bool)
    mask[vs, us] = True
    return SphereView(out, mask)
