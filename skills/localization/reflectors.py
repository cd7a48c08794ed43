"""Laser-reflector landmarks: extraction, triangle matching, trilateration, particle weights.

After ``reflector-amcl-tracking-grasp`` section 3.1 (the method of de Miguel et al. with
the weights fed into AMCL):

1. **Extraction** (:func:`extract_reflectors`): runs of consecutive beams whose return
   intensity is at least ``intensity_threshold`` are one reflector each; its centre is the
   circle of the known post radius fitted (Gauss-Newton) to the run's hit points, i.e. the
   surface hits corrected outwards by the post radius (one beam: ``pi/4`` of the radius
   behind the hit, the mean depth of a post's surface under a beam at a random offset).
2. **Template library** (:class:`TriangleLibrary`): every triangle of three map reflectors,
   its sides sorted longest first, the library sorted by the longest side (section 3.1.1).
3. **Triangle matching** (:func:`match_reflectors`): each triangle of detected reflectors is
   looked up by its longest side and confirmed on the other two within ``side_tolerance``
   (section 3.1.2); every candidate correspondence is scored by how many detections a rigid
   fit of it explains (robust to a spurious detection and to a missing reflector), and the
   best is kept.
4. **Trilateration** (:func:`trilaterate`, equation 1) by linear least squares refined by
   Gauss-Newton on the ranges, and the **heading** (equation 2) as the circular mean of
   ``atan2(y_i - y_G, x_i - x_G) - phi_i`` (the paper's case analysis is ``atan2``; a plain
   arithmetic mean breaks at +-pi).
5. **Weights** (equations 3, 4, 6; :func:`position_weight`, :func:`orientation_score`):
   ``omega_new = alpha * s * omega + beta * d`` with ``alpha = 154``, ``beta = 1``, each
   term normalised over the particle set (:mod:`.amcl`).

Where the paper is ambiguous, and what we chose (also in docs/localization.md):

* Equation 3 uses an identity covariance: with metres and radians that is a 1 m / 1 rad
  spread, flat at the centimetre scale, and equation 7's ``lambda = 1`` injects particles
  a metre away. We use a diagonal covariance ``(sigma_xy, sigma_xy, sigma_theta)`` for
  ``d`` and the same spread for the injected particles; the defaults (3 cm, 0.03 rad) are
  a few times the trilateration's own error.
* Equation 4 names "the mean and standard deviation of the observation angle" without
  saying of what. We read ``s`` as the orientation score of a particle: the mean over the
  matched reflectors of a Gaussian (std ``sigma_bearing``) of the difference between the
  bearing at which the particle would see the reflector and the bearing observed.
* Equation 6 gives no scale for omega, s and d. We normalise ``s * omega`` and ``d`` over
  the particle set before mixing them, so ``alpha : beta`` is the share of the weight
  each carries whatever the particle count and spreads (:mod:`.amcl`).
* Equations 7 and 8 add a new particle around the fix with probability ``d_i`` where
  ``d_i > 0.01``, a figure that depends on the units of equation 3. We replace a fixed
  share, ``inject_fraction``, of the resampled set by particles drawn around the fix.
* A post is not always two beams wide: at 0.9 degrees a 5 cm post is one beam beyond
  3.2 m, and the lab's three posts are then one beam each. ``min_beams`` is 1.

Frames: detections are in the lidar frame (x forward, CCW angles); map reflectors and
robot poses in ``map``.
"""

from __future__ import annotations

import bisect
import itertools
import math
from dataclasses import dataclass

import numpy as np

from mmexec.drivers.geometry import rigid_fit
from mmexec.drivers.geometry import wrap_angle as wrap

__all__ = [
    "Detection",
    "ReflectorConfig",
    "ReflectorFix",
    "TriangleLibrary",
    "extract_reflectors",
    "fix_from_scan",
    "heading_from_bearings",
    "match_reflectors",
    "orientation_score",
    "position_weight",
    "trilaterate",
]


@dataclass(frozen=True)
class ReflectorConfig:
    """Reflector detection, matching and weighting parameters."""

    #: beams at or above this intensity (0..1) are reflector returns
    intensity_threshold: float = 0.8
    #: radius of the reflector posts [m]
    post_radius: float = 0.04
    #: fewest beams on one reflector (1: a post narrower than two beam spacings at its
    #: range still counts, its centre placed behind the single hit, see ``_fit_post``)
    min_beams: int = 1
    #: detections farther than this are ignored [m]
    max_range: float = 8.0
    #: side-length tolerance of triangle matching [m]
    side_tolerance: float = 0.06
    #: a detection within this distance of a map reflector under a fit is an inlier [m]
    inlier_distance: float = 0.10
    #: equation 6's alpha (orientation score weight) and beta (position weight)
    alpha: float = 154.0
    beta: float = 1.0
    #: equation 3's position / heading spread [m], [rad] (the paper: 1 and 1)
    sigma_xy: float = 0.03
    sigma_theta: float = 0.03
    #: equation 4's bearing spread [rad] (a post's bearing is good to about half a beam
    #: spacing: 0.008 rad at 0.9 degrees)
    sigma_bearing: float = 0.01
    #: share of the particle set replaced by particles drawn around the fix (equation 7)
    inject_fraction: float = 0.1


@dataclass(frozen=True)
class Detection:
    """One reflector seen in a scan: centre ``(x, y)`` [m] in the lidar frame, its range
    [m] and bearing [rad, CCW] from the lidar, and how many beams hit it."""

    x: float
    y: float
    range: float
    bearing: float
    beams: int


@dataclass(frozen=True)
class ReflectorFix:
    """The robot pose given by matched reflectors.

    ``pose``: ``(x, y, theta)`` of ``base_link`` in ``map``; ``ids``: the map reflector of
    each used detection; ``residual``: RMS range residual of the trilateration [m].
    """

    pose: np.ndarray
    ids: tuple[int, ...]
    detections: tuple[Detection, ...]
    residual: float


# --------------------------------------------------------------------------- extraction


def _runs(mask: np.ndarray) -> list[np.ndarray]:
    """Index arrays of the runs of True in a circular ``mask`` (a run may wrap past the end)."""
    n = len(mask)
    if n == 0 or not mask.any():
        return []
    if mask.all():
        return [np.arange(n)]
    start = int(np.flatnonzero(~mask)[0]) + 1  # begin just after a False: no run is split
    order = (np.arange(n) + start) % n
    m = mask[order]
    edges = np.flatnonzero(np.diff(np.concatenate(([0], m.astype(np.int8), [0]))))
    return [order[a:b] for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _fit_post(px: np.ndarray, py: np.ndarray, radius: float) -> tuple[float, float]:
    """Centre of the circle of ``radius`` best fitting the hit points (seen from the origin).

    One hit point says only where along its beam the surface was: the centre is taken
    ``pi/4 * radius`` behind it, the mean depth of the post's surface under a beam that
    crosses the post at a uniformly random offset (pushing back by the full radius would
    place every single-beam post 0.21 radius too far)."""
    mx, my = float(px.mean()), float(py.mean())
    d = math.hypot(mx, my)
    if len(px) == 1:
        push = 0.25 * math.pi * radius
        return mx + push * mx / d, my + push * my / d
    cx, cy = mx + radius * mx / d, my + radius * my / d  # surface point pushed back by r
    for _ in range(5):  # Gauss-Newton on sum (|p - c| - r)^2
        ex, ey = cx - px, cy - py
        dist = np.hypot(ex, ey)
        dist = np.where(dist < 1e-9, 1e-9, dist)
        res = dist - radius
        jac = np.stack([ex / dist, ey / dist], axis=1)
        jtj = jac.T @ jac
        if abs(np.linalg.det(jtj)) < 1e-12:
            break
        step = np.linalg.solve(jtj, jac.T @ res)
        cx, cy = cx - float(step[0]), cy - float(step[1])
        if math.hypot(float(step[0]), float(step[1])) < 1e-6:
            break
    # A fit that wandered (two beams on a tiny arc) falls back to the pushed-back mean.
    if math.hypot(cx - mx, cy - my) > 2.0 * radius:
        cx, cy = mx + radius * mx / d, my + radius * my / d
    return cx, cy


def extract_reflectors(
    ranges: np.ndarray,
    angles: np.ndarray,
    intensities: np.ndarray | None,
    cfg: ReflectorConfig,
) -> list[Detection]:
    """The reflectors in one scan (lidar frame), from its high-intensity beam runs."""
    if intensities is None:
        return []
    ok = np.isfinite(ranges) & (ranges > 0) & (ranges <= cfg.max_range)
    bright = ok & (intensities >= cfg.intensity_threshold)
    out: list[Detection] = []
    for run in _runs(bright):
        if len(run) < cfg.min_beams:
            continue
        px = ranges[run] * np.cos(angles[run])
        py = ranges[run] * np.sin(angles[run])
        cx, cy = _fit_post(px, py, cfg.post_radius)
        out.append(Detection(cx, cy, math.hypot(cx, cy), math.atan2(cy, cx), len(run)))
    return out


# --------------------------------------------------------------------------- triangles


def _sides(p: np.ndarray, i: int, j: int, k: int) -> tuple[tuple[float, float, float], tuple[int, int, int]]:
    """Sides of triangle ``ijk`` longest first and its vertices in the canonical order
    ``(A, B, C)``: A joins the longest and middle sides, B the longest and shortest."""
    d = {
        (i, j): float(np.hypot(*(p[i] - p[j]))),
        (i, k): float(np.hypot(*(p[i] - p[k]))),
        (j, k): float(np.hypot(*(p[j] - p[k]))),
    }
    (e1, l1), (e2, l2), (e3, l3) = sorted(d.items(), key=lambda kv: -kv[1])
    a = (set(e1) & set(e2)).pop()
    b = (set(e1) & set(e3)).pop()
    c = (set(e2) & set(e3)).pop()
    return (l1, l2, l3), (a, b, c)


class TriangleLibrary:
    """Every triangle of the map's reflectors (section 3.1.1), sorted by longest side.

    ``reflectors``: ``(K, 2)`` centres [m] in ``map``.
    """

    def __init__(self, reflectors: np.ndarray, min_side: float = 0.2) -> None:
        self.reflectors = np.asarray(reflectors, dtype=np.float64).reshape(-1, 2)
        entries = []
        for i, j, k in itertools.combinations(range(len(self.reflectors)), 3):
            sides, verts = _sides(self.reflectors, i, j, k)
            if sides[2] >= min_side:  # a degenerate sliver identifies nothing
                entries.append((sides, verts))
        entries.sort(key=lambda e: e[0][0])
        self.sides = [e[0] for e in entries]
        self.vertices = [e[1] for e in entries]
        self._longest = [s[0] for s in self.sides]

    def __len__(self) -> int:
        return len(self.sides)

    def lookup(self, sides: tuple[float, float, float], tol: float) -> list[tuple[int, int, int]]:
        """Canonical vertex triples of the library triangles matching ``sides`` (longest
        first) within ``tol`` [m] on every side."""
        lo = bisect.bisect_left(self._longest, sides[0] - tol)
        hi = bisect.bisect_right(self._longest, sides[0] + tol)
        return [
            self.vertices[n]
            for n in range(lo, hi)
            if abs(self.sides[n][1] - sides[1]) <= tol and abs(self.sides[n][2] - sides[2]) <= tol
        ]


def match_reflectors(
    detections: list[Detection], library: TriangleLibrary, cfg: ReflectorConfig
) -> dict[int, int]:
    """Detection index -> map reflector id, from triangle matching; empty below three
    matches. Every library match of every detected triangle is a hypothesis; the one whose
    rigid fit puts the most detections within ``inlier_distance`` of a map reflector wins
    (ties: the smaller residual)."""
    if len(detections) < 3 or len(library) == 0:
        return {}
    obs = np.array([[d.x, d.y] for d in detections])
    refl = library.reflectors
    best: tuple[int, float, dict[int, int]] = (0, math.inf, {})
    tried: set[tuple[int, ...]] = set()
    for i, j, k in itertools.combinations(range(len(obs)), 3):
        sides, (a, b, c) = _sides(obs, i, j, k)
        for ma, mb, mc in library.lookup(sides, cfg.side_tolerance):
            key = (a, ma, b, mb, c, mc)
            if key in tried:
                continue
            tried.add(key)
            r, t = rigid_fit(obs[[a, b, c]], refl[[ma, mb, mc]])
            moved = obs @ r.T + t
            dist = np.hypot(moved[:, None, 0] - refl[None, :, 0], moved[:, None, 1] - refl[None, :, 1])
            nearest = dist.argmin(axis=1)
            near_d = dist[np.arange(len(obs)), nearest]
            assign: dict[int, int] = {}
            for det in np.argsort(near_d):
                if near_d[det] <= cfg.inlier_distance and int(nearest[det]) not in assign.values():
                    assign[int(det)] = int(nearest[det])
            if len(assign) < 3:
                continue
            err = float(np.mean([near_d[d] for d in assign]))
            if len(assign) > best[0] or (len(assign) == best[0] and err < best[1]):
                best = (len(assign), err, assign)
    return best[2]


# --------------------------------------------------------------------------- pose fix


def trilaterate(centres: np.ndarray, ranges: np.ndarray) -> tuple[np.ndarray, float]:
    """Position ``(x, y)`` [m] solving equation 1 by least squares, and the RMS range
    residual [m]. ``centres`` ``(n, 2)`` map reflectors, ``ranges`` ``(n,)``; n >= 3."""
    p = np.asarray(centres, dtype=np.float64)
    r = np.asarray(ranges, dtype=np.float64)
    # Linear: subtract the last circle's equation from the others.
    a = 2.0 * (p[-1] - p[:-1])
    b = r[:-1] ** 2 - r[-1] ** 2 - np.sum(p[:-1] ** 2, axis=1) + np.sum(p[-1] ** 2)
    xy = np.linalg.lstsq(a, b, rcond=None)[0]
    for _ in range(10):  # Gauss-Newton on the ranges themselves
        diff = xy - p
        dist = np.hypot(diff[:, 0], diff[:, 1])
        dist = np.where(dist < 1e-9, 1e-9, dist)
        jac = diff / dist[:, None]
        step = np.linalg.lstsq(jac, dist - r, rcond=None)[0]
        xy = xy - step
        if float(np.hypot(*step)) < 1e-7:
            break
    dist = np.hypot(*(xy - p).T)
    return xy, float(np.sqrt(np.mean((dist - r) ** 2)))


def heading_from_bearings(position: np.ndarray, centres: np.ndarray, bearings: np.ndarray) -> float:
    """Heading [rad] of the sensor at ``position`` seeing ``centres`` at ``bearings``
    (equation 2), as a circular mean."""
    d = centres - position
    est = np.arctan2(d[:, 1], d[:, 0]) - bearings
    return float(math.atan2(np.mean(np.sin(est)), np.mean(np.cos(est))))


def fix_from_scan(
    ranges: np.ndarray,
    angles: np.ndarray,
    intensities: np.ndarray | None,
    library: TriangleLibrary,
    cfg: ReflectorConfig,
    mount: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> ReflectorFix | None:
    """The base pose from the reflectors in one scan, or None below three matches.

    ``mount``: the lidar pose ``(x, y, yaw)`` in ``base_link``.
    """
    dets = extract_reflectors(ranges, angles, intensities, cfg)
    assign = match_reflectors(dets, library, cfg)
    if len(assign) < 3:
        return None
    used = sorted(assign)
    centres = library.reflectors[[assign[i] for i in used]]
    rng = np.array([dets[i].range for i in used])
    brg = np.array([dets[i].bearing for i in used])
    lxy, residual = trilaterate(centres, rng)
    lyaw = heading_from_bearings(lxy, centres, brg)
    # base = lidar pose composed with the inverse mount
    mx, my, myaw = mount
    yaw = lyaw - myaw
    c, s = math.cos(yaw), math.sin(yaw)
    bx = lxy[0] - (c * mx - s * my)
    by = lxy[1] - (s * mx + c * my)
    pose = np.array([bx, by, float(wrap(yaw))])
    return ReflectorFix(pose, tuple(assign[i] for i in used), tuple(dets[i] for i in used), residual)


# --------------------------------------------------------------------------- weights


def position_weight(particles: np.ndarray, fix: np.ndarray, cfg: ReflectorConfig) -> np.ndarray:
    """Equation 3's ``d`` per particle: a Gaussian of the particle's offset from the fix,
    with the diagonal spread ``(sigma_xy, sigma_xy, sigma_theta)`` (see the module note)."""
    dx = (particles[:, 0] - fix[0]) / cfg.sigma_xy
    dy = (particles[:, 1] - fix[1]) / cfg.sigma_xy
    dt = wrap(particles[:, 2] - fix[2]) / cfg.sigma_theta
    norm = (2.0 * math.pi) ** 1.5 * cfg.sigma_xy * cfg.sigma_xy * cfg.sigma_theta
    return np.exp(-0.5 * (dx * dx + dy * dy + dt * dt)) / norm


def orientation_score(
    particles: np.ndarray,
    centres: np.ndarray,
    bearings: np.ndarray,
    cfg: ReflectorConfig,
    mount: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> np.ndarray:
    """Equation 4's ``s`` per particle: the mean Gaussian score of the difference between
    the bearing [rad, lidar frame] at which the particle would see each matched reflector
    and the bearing observed."""
    mx, my, myaw = mount
    c, s = np.cos(particles[:, 2]), np.sin(particles[:, 2])
    lx = particles[:, 0] + c * mx - s * my
    ly = particles[:, 1] + s * mx + c * my
    pred = np.arctan2(centres[None, :, 1] - ly[:, None], centres[None, :, 0] - lx[:, None])
    pred = pred - (particles[:, 2:3] + myaw)
    dev = wrap(pred - bearings[None, :])
    g = np.exp(-0.5 * (dev / cfg.sigma_bearing) ** 2) / (cfg.sigma_bearing * math.sqrt(2.0 * math.pi))
    return g.mean(axis=1)
