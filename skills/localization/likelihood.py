"""Likelihood-field range-finder model over an occupancy map (Probabilistic Robotics 6.4).

The distance from every map cell to the nearest occupied cell is computed once per map
(an exact Euclidean distance transform, OpenCV's ``DIST_MASK_PRECISE``) and clamped at
``max_occ_dist``; scoring a scan is then one table look-up per beam end point. A beam end
point at distance ``z`` [m] from the nearest obstacle has probability
``pz = z_hit * exp(-z^2 / (2 sigma_hit^2)) + z_rand / range_max``; beams at or beyond
``range_max`` (no return) are skipped and end points off the map count as ``max_occ_dist``
away, as in ROS ``amcl``'s ``likelihood_field`` model. Also as there, the beams of a scan
are combined as ``p = 1 + sum(pz^3)`` (ROS's heuristic against the overconfidence of a
product of correlated beams) and that ``p`` multiplies the particle's weight.

Frames: particles are ``(x, y, theta)`` of ``base_link`` in ``map``; the lidar's mount
``(x, y, yaw)`` in ``base_link``; beam angles CCW in the lidar frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from mmexec.drivers.interfaces import OccupancyGrid

__all__ = ["BeamModel", "LikelihoodField"]


@dataclass(frozen=True)
class BeamModel:
    """Sensor-model parameters (ROS ``laser_*`` names and defaults, except ``sigma_hit``)."""

    #: mixture weight of a hit (the rest is ``z_rand``)
    z_hit: float = 0.95
    #: mixture weight of a random reading
    z_rand: float = 0.05
    #: std dev of the hit Gaussian [m] (ROS: 0.2; 0.1 here: two cells of a 5 cm map plus
    #: the lidar's centimetre noise)
    sigma_hit: float = 0.1
    #: distance-transform clamp [m] (``laser_likelihood_max_dist``)
    max_occ_dist: float = 2.0
    #: beams used per scan, evenly spread (``laser_max_beams``)
    max_beams: int = 60


class LikelihoodField:
    """The distance field of ``grid`` and the scan likelihood of particles against it.

    Cells with value >= ``occupied`` are obstacles; unknown cells (-1) are not.
    """

    def __init__(self, grid: OccupancyGrid, model: BeamModel | None = None, occupied: int = 65) -> None:
        self.grid = grid
        self.model = model or BeamModel()
        obstacle = grid.data >= occupied
        # distanceTransform measures to the nearest ZERO pixel: obstacles are the zeros.
        src = np.where(obstacle, 0, 255).astype(np.uint8)
        if obstacle.any():
            dist = cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE).astype(np.float64)
            dist *= grid.resolution
        else:
            dist = np.full(grid.data.shape, np.inf)
        self.distance = np.minimum(dist, self.model.max_occ_dist)
        # the field with a one-cell border at max_occ_dist: a clipped index then reads
        # max_occ_dist for any point off the map (one gather, no masks)
        self._padded = np.pad(self.distance, 1, constant_values=self.model.max_occ_dist).ravel()
        o = grid.origin
        self._origin = (o.x, o.y, math.cos(o.theta), math.sin(o.theta))

    def distance_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Distance [m] to the nearest obstacle of map points ``(x, y)`` (any equal shapes),
        ``max_occ_dist`` off the map."""
        ox, oy, c, s = self._origin
        dx, dy = x - ox, y - oy
        res = self.grid.resolution
        col = np.floor((c * dx + s * dy) / res + 1e-9)
        row = np.floor((-s * dx + c * dy) / res + 1e-9)
        h, w = self.distance.shape
        # into the border (-1 or the size) when off the map; fmax/fmin send nan there too
        col = np.fmin(np.fmax(col, -1.0, out=col), w, out=col)
        row = np.fmin(np.fmax(row, -1.0, out=row), h, out=row)
        return self._padded.take((row.astype(np.int64) + 1) * (w + 2) + col.astype(np.int64) + 1)

    def beam_subset(self, ranges: np.ndarray, angles: np.ndarray, range_max: float) -> tuple[np.ndarray, np.ndarray]:
        """At most ``max_beams`` evenly spaced beams with a return (``range < range_max``)."""
        ok = np.isfinite(ranges) & (ranges < range_max) & (ranges > 0)
        idx = np.flatnonzero(ok)
        if len(idx) > self.model.max_beams:
            idx = idx[np.linspace(0, len(idx) - 1, self.model.max_beams).round().astype(np.int64)]
        return ranges[idx], angles[idx]

    def scan_likelihood(
        self,
        particles: np.ndarray,
        ranges: np.ndarray,
        angles: np.ndarray,
        range_max: float,
        mount: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> np.ndarray:
        """``p`` per particle ``(N,)`` for the beams ``ranges`` [m] at ``angles`` [rad, lidar
        frame] (already subsampled, see :meth:`beam_subset`); ``mount`` is the lidar pose in
        ``base_link``."""
        m = self.model
        if len(ranges) == 0:
            return np.ones(len(particles))
        mx, my, myaw = mount
        # beam end points in base_link (B,)
        bx = mx + ranges * np.cos(angles + myaw)
        by = my + ranges * np.sin(angles + myaw)
        c, s = np.cos(particles[:, 2])[:, None], np.sin(particles[:, 2])[:, None]
        px = particles[:, 0:1] + c * bx - s * by
        py = particles[:, 1:2] + s * bx + c * by
        z = self.distance_at(px, py)
        pz = m.z_hit * np.exp(-(z * z) / (2.0 * m.sigma_hit * m.sigma_hit)) + m.z_rand / range_max
        return 1.0 + np.sum(pz * pz * pz, axis=1)
