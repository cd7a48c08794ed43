"""Obstacles from a planar lidar scan: beams -> points in ``map`` -> clusters -> circles.

The pipeline (each step vectorised over the beams):

1. :func:`scan_to_map` puts every beam in ``map``: the sensor origin, unit directions, the
   hit points of beams with a valid return, and how far each beam saw free space (for the
   costmap's clearing).
2. The caller decides which hits are *new* (not on the static map's occupied cells); the
   rolling costmap does this (:meth:`mmexec.skills.navigation.costmap.RollingCostmap.update`).
3. :func:`cluster_points` splits the new hits, in scan order, where two consecutive points
   are farther apart than ``cluster_gap`` (the static or missing points between them are
   ignored, so the two legs of a person in front of a wall stay one cluster), joins the
   last and first clusters of a full 360 degree scan, and cuts clusters longer than
   ``2 * max_radius`` (a new wall, a moved table) into chunks.
4. :func:`fit_circles` gives each cluster a circle that covers all its points: the
   centroid and the largest centroid-to-point distance (at least ``min_radius``). As in
   the UR3e paper (section 4.3, "the obstacle can be confined within a circle of radius
   r_u"), the radius used for safety, ``safety_radius``, is that covering radius plus the
   robot's footprint radius plus a margin, so the robot's *centre* must stay outside it.

The lidar sees only the near side of an object; the centroid of the visible arc lies in
front of the true centre and the covering circle does not cover the hidden back. The near
side is what the robot can hit, and the safety radius adds the robot radius and a margin
on top, so this is accepted; :data:`ObstacleConfig.min_radius` keeps a one-point cluster
from becoming a zero-size circle.

Frames: points and circles are in ``map`` [m]; velocities [m/s] in ``map``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from mmexec.drivers.interfaces import LaserScan, Pose2D
from mmexec.skills.navigation.checks import non_negative, positive

__all__ = [
    "Circles",
    "ObstacleConfig",
    "ScanPoints",
    "cluster_points",
    "detect_obstacles",
    "drop_within",
    "fit_circles",
    "scan_to_map",
]


@dataclass(frozen=True)
class ObstacleConfig:
    """Clustering and circle fitting. Distances in m.

    ``robot_radius`` and ``margin`` make the safety radius (the paper's ``r_u``):
    ``covering radius + robot_radius + margin``.
    """

    cluster_gap: float = 0.20
    min_points: int = 2
    max_radius: float = 0.40
    min_radius: float = 0.05
    robot_radius: float = 0.178
    margin: float = 0.05

    def validate(self) -> list[str]:
        errs = positive(self, "cluster_gap", "max_radius", "min_radius") + non_negative(self, "robot_radius", "margin")
        if self.min_points < 1:
            errs.append(f"min_points: must be >= 1, got {self.min_points}")
        if self.min_radius > self.max_radius:
            errs.append(f"min_radius {self.min_radius} m exceeds max_radius {self.max_radius} m")
        return errs


def _empty2() -> np.ndarray:
    return np.zeros((0, 2))


@dataclass(frozen=True)
class Circles:
    """Obstacle circles in ``map``, one row each.

    ``centres`` (k, 2) [m]; ``radii`` (k,) [m], covering the obstacle's points;
    ``safety_radii`` (k,) [m], the radius the robot *centre* must stay out of (covering
    radius + robot radius + margin); ``velocities`` (k, 2) [m/s] (zero when untracked);
    ``ids`` (k,) track ids (-1 when untracked); ``person`` (k,) True for a track
    classified as a person (it moved).
    """

    centres: np.ndarray = field(default_factory=_empty2)
    radii: np.ndarray = field(default_factory=lambda: np.zeros(0))
    safety_radii: np.ndarray = field(default_factory=lambda: np.zeros(0))
    velocities: np.ndarray = field(default_factory=_empty2)
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    person: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def __len__(self) -> int:
        return int(self.centres.shape[0])

    def at_time(self, t: float) -> np.ndarray:
        """Centres (k, 2) predicted ``t`` [s] ahead at constant velocity."""
        return self.centres + t * self.velocities

    def paths(self, times: np.ndarray) -> np.ndarray:
        """Centres predicted at each of ``times`` (K,) [s]: shape (k, K, 2)."""
        return self.centres[:, None, :] + times[None, :, None] * self.velocities[:, None, :]

    def select(self, mask: np.ndarray) -> Circles:
        """The rows where ``mask`` is True."""
        return Circles(self.centres[mask], self.radii[mask], self.safety_radii[mask],
                       self.velocities[mask], self.ids[mask], self.person[mask])

    @property
    def people(self) -> Circles:
        return self.select(self.person)


@dataclass(frozen=True)
class ScanPoints:
    """One scan in ``map``, per beam (``n`` beams, in scan order).

    ``origin`` (2,) sensor position [m]; ``directions`` (n, 2) unit beam directions;
    ``hit`` (n,) True where the beam returned within ``[range_min, range_max)``;
    ``xy`` (n, 2) hit points [m] (nan where no hit); ``free`` (n,) how far [m] the beam
    saw free space (its range for a hit, ``clear_range`` for no return, 0 for a beam not
    measured); ``full_circle``: the beams cover 360 degrees (the first and last beams
    are neighbours); ``angle0`` [rad] the first beam's direction in ``map`` and
    ``increment`` [rad] the signed step between beams in ``map`` (negative for a lidar
    mounted upside down).
    """

    origin: np.ndarray
    directions: np.ndarray
    hit: np.ndarray
    xy: np.ndarray
    free: np.ndarray
    full_circle: bool
    angle0: float
    increment: float

    def beam_towards(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For map points ``xy`` (m, 2): the index of the beam whose direction is nearest
        to each point's bearing from the sensor, and whether that beam exists (a point
        outside a partial scan's field of view has none)."""
        bearing = np.arctan2(xy[:, 1] - self.origin[1], xy[:, 0] - self.origin[0])
        rel = np.mod(bearing - self.angle0 + math.pi, 2.0 * math.pi) - math.pi  # (-pi, pi]
        steps = rel / self.increment
        n = self.n_beams
        if self.full_circle:
            idx = np.mod(np.rint(steps).astype(np.int64), n)
            return idx, np.ones(idx.shape, dtype=bool)
        steps = np.where(steps < -0.5, steps + 2.0 * math.pi / abs(self.increment), steps)
        idx = np.rint(steps).astype(np.int64)
        ok = (idx >= 0) & (idx < n)
        return np.clip(idx, 0, n - 1), ok

    @property
    def n_beams(self) -> int:
        return int(self.hit.shape[0])


def scan_to_map(scan: LaserScan, pose: Pose2D, clear_range: float) -> ScanPoints:
    """Beams of ``scan`` (lidar frame) in ``map``, with the base at ``pose`` in ``map`` and
    the lidar at ``scan.T_base_lidar`` (a planar mount: its z axis up or down).

    ``clear_range`` [m]: how far a beam without a return (inf, or at ``range_max``) is
    taken to have seen free space; nan beams (not measured) see nothing.
    """
    T = pose.matrix() @ np.asarray(scan.T_base_lidar, dtype=float)
    R = T[:2, :2]
    origin = T[:2, 3].copy()
    ang = scan.angles
    local = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    directions = local @ R.T
    r = np.asarray(scan.ranges, dtype=float)
    measured = ~np.isnan(r)
    with np.errstate(invalid="ignore"):
        hit = measured & np.isfinite(r) & (r >= scan.range_min) & (r < scan.range_max)
    no_return = measured & ~hit & ~(r < scan.range_min)
    free = np.where(hit, r, np.where(no_return, min(clear_range, scan.range_max), 0.0))
    xy = np.where(hit[:, None], origin + directions * np.where(hit, r, 0.0)[:, None], np.nan)
    span = abs(scan.angle_increment) * len(r)
    full = bool(span >= 2.0 * math.pi - 1.5 * abs(scan.angle_increment))
    angle0 = math.atan2(directions[0, 1], directions[0, 0]) if len(r) else 0.0
    mirrored = float(np.linalg.det(R)) < 0.0
    increment = -scan.angle_increment if mirrored else scan.angle_increment
    return ScanPoints(origin, directions, hit, xy, free, full, angle0, float(increment))


def drop_within(points: ScanPoints, centre: tuple[float, float], radius: float) -> ScanPoints:
    """``points`` with the hits within ``radius`` [m] of ``centre`` (map, [m]) taken as
    beams not measured (no hit, nothing seen free): returns off the robot's own body
    (a base-mounted lidar's beams that meet the arm's base behind it), which say nothing
    about the room beyond. ``radius`` <= 0: ``points`` unchanged."""
    if radius <= 0.0 or not points.hit.any():
        return points
    with np.errstate(invalid="ignore"):
        own = points.hit & (np.hypot(points.xy[:, 0] - centre[0], points.xy[:, 1] - centre[1]) < radius)
    if not own.any():
        return points
    xy = points.xy.copy()
    xy[own] = np.nan
    return replace(points, hit=points.hit & ~own, xy=xy, free=np.where(own, 0.0, points.free))


def cluster_points(xy: np.ndarray, gap: float, max_radius: float, *, wrap: bool = False) -> np.ndarray:
    """Cluster labels ``0..k-1`` of the points ``xy`` (m, 2) [m], given in scan order.

    A new cluster starts where consecutive points are more than ``gap`` [m] apart, and
    again each time the path length along a cluster passes another ``2 * max_radius``
    [m], so no cluster is longer than that. With ``wrap`` (a full-circle scan) the last
    cluster joins the first when their end points are within ``gap`` (and the joined
    cluster keeps within the length bound).
    """
    m = xy.shape[0]
    if m == 0:
        return np.zeros(0, dtype=np.int64)
    step = np.zeros(m)
    step[1:] = np.hypot(*(xy[1:] - xy[:-1]).T)
    brk = np.zeros(m, dtype=bool)
    brk[0] = True
    brk[1:] = step[1:] > gap
    # path length since the cluster's first point: cumsum minus its value at the start
    step_in = np.where(brk, 0.0, step)
    cum = np.cumsum(step_in)
    start_cum = np.maximum.accumulate(np.where(brk, cum, -np.inf))
    chunk = np.floor((cum - start_cum) / (2.0 * max_radius)).astype(np.int64)
    new = brk.copy()
    new[1:] |= chunk[1:] != chunk[:-1]
    labels = np.cumsum(new) - 1
    k = int(labels[-1]) + 1
    if wrap and k > 1:
        closing = math.hypot(*(xy[0] - xy[-1]))
        starts = np.flatnonzero(new)
        first_len = cum[starts[1] - 1] - cum[0]
        last_len = cum[-1] - cum[starts[-1]]
        if closing <= gap and first_len + closing + last_len <= 2.0 * max_radius:
            labels = np.where(labels == k - 1, 0, labels)
    return labels


def fit_circles(xy: np.ndarray, labels: np.ndarray, config: ObstacleConfig) -> Circles:
    """One covering circle per label with at least ``config.min_points`` points.

    Centre: the centroid of the cluster's points; radius: the largest centroid-to-point
    distance, at least ``min_radius``; safety radius: radius + ``robot_radius`` +
    ``margin``. Labels need not be contiguous runs; empty or small labels are dropped.
    """
    if labels.size == 0:
        return Circles()
    k = int(labels.max()) + 1
    counts = np.bincount(labels, minlength=k)
    cx = np.bincount(labels, weights=xy[:, 0], minlength=k)
    cy = np.bincount(labels, weights=xy[:, 1], minlength=k)
    keep = counts >= config.min_points
    with np.errstate(invalid="ignore", divide="ignore"):
        centres = np.stack([cx / counts, cy / counts], axis=1)
    d = np.hypot(*(xy - centres[labels]).T)
    radius = np.zeros(k)
    np.maximum.at(radius, labels, d)
    radius = np.maximum(radius, config.min_radius)
    centres, radius = centres[keep], radius[keep]
    n = centres.shape[0]
    return Circles(
        centres=centres,
        radii=radius,
        safety_radii=radius + config.robot_radius + config.margin,
        velocities=np.zeros((n, 2)),
        ids=np.full(n, -1, dtype=np.int64),
        person=np.zeros(n, dtype=bool),
    )


def detect_obstacles(points: ScanPoints, new: np.ndarray, config: ObstacleConfig) -> Circles:
    """Circles around the clusters of the hits marked ``new`` (n_beams,) bool: hits that
    are not part of the static map (see the module docstring)."""
    sel = points.hit & new
    xy = points.xy[sel]
    labels = cluster_points(xy, config.cluster_gap, config.max_radius, wrap=points.full_circle)
    return fit_circles(xy, labels, config)
