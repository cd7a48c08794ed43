"""Tracking of obstacle circles between scans: velocity estimates, people told from furniture.

Each track holds a position and a velocity in ``map`` and is updated by an alpha-beta
filter (a steady-state constant-velocity Kalman filter): with the prediction
``p' = p + v dt`` and the residual ``r = z - p'`` of the associated detection ``z``,
``p = p' + alpha r`` and ``v = v + (beta / dt) r``. The filter follows a constant
velocity without lag, so a person walking at 1 m/s reads 1 m/s after a few scans.

Association is greedy nearest-neighbour on the predicted positions within ``gate`` [m]
(the closest pair first), which is enough for the few obstacles near a base. A detection
that matches no track starts one (velocity zero); a track not seen for ``max_age`` [s]
is dropped, and until then it coasts at its velocity (a person briefly hidden behind
another stays an obstacle).

People vs furniture: a track becomes a person when (a) its covering radius is at most
``person_radius`` (a person seen by a planar lidar at leg or hip height is smaller than
a sofa or a chunk of a new wall), (b) its speed stays above ``moving_speed`` [m/s] for
``confirm`` consecutive updates, and (c) it has travelled at least ``min_travel`` [m]
from where it was first seen. The last test is what tells people from furniture: the
centroid of a chair's visible side wanders (another side comes into view, a person walks
in front of it and hides part of it), which can look like speed for a few scans, but it
stays within the chair. A person stays a person (people stop, and keep their social
space while they stand). Only people's velocities are reported; other tracks report
zero (furniture does not move, and a noisy velocity would only shake the barriers).
Frames: ``map``, metres, seconds.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from mmexec.skills.navigation.checks import checked, positive
from mmexec.skills.navigation.obstacles import Circles

__all__ = ["ObstacleTracker", "TrackingConfig"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrackingConfig:
    """Alpha-beta gains (dimensionless, 0 < alpha <= 1, 0 < beta < 4 - 2 alpha for a
    stable filter), association ``gate`` [m], ``max_age`` [s], speed threshold for a
    person ``moving_speed`` [m/s] held for ``confirm`` updates, ``min_travel`` [m] from
    where it was first seen, covering radius at most ``person_radius`` [m]; speed cap
    ``max_speed`` [m/s]."""

    alpha: float = 0.5
    beta: float = 0.15
    gate: float = 0.5
    max_age: float = 0.5
    moving_speed: float = 0.25
    confirm: int = 4
    min_travel: float = 0.5
    person_radius: float = 0.35
    max_speed: float = 2.5

    def validate(self) -> list[str]:
        errs = []
        if not 0 < self.alpha <= 1:
            errs.append(f"alpha: must be in (0, 1], got {self.alpha}")
        if not 0 < self.beta < 4 - 2 * self.alpha:
            errs.append(f"beta: must be in (0, 4 - 2 alpha) for a stable filter, got {self.beta}")
        errs += positive(self, "gate", "max_age", "moving_speed", "min_travel", "person_radius", "max_speed")
        if self.confirm < 1:
            errs.append(f"confirm: must be >= 1, got {self.confirm}")
        return errs


class ObstacleTracker:
    """Tracks obstacle circles over time. :meth:`update` once per scan with the scan's
    stamp [s]; it returns the tracked circles (velocities, ids and person flags filled),
    including tracks that coast unseen for up to ``max_age``."""

    def __init__(self, config: TrackingConfig | None = None) -> None:
        self.config = checked(config or TrackingConfig())
        self._next_id = 0
        self.reset()

    def reset(self) -> None:
        """Forget every track (ids keep counting up)."""
        self._pos = np.zeros((0, 2))
        self._born = np.zeros((0, 2))
        self._vel = np.zeros((0, 2))
        self._radius = np.zeros(0)
        self._safety = np.zeros(0)
        self._ids = np.zeros(0, dtype=np.int64)
        self._seen = np.zeros(0)
        self._moving = np.zeros(0, dtype=np.int64)
        self._person = np.zeros(0, dtype=bool)
        self._t: float | None = None

    def __len__(self) -> int:
        return int(self._ids.size)

    def _associate(self, pred: np.ndarray, det: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Greedy nearest pairs (track index, detection index) within the gate."""
        if pred.shape[0] == 0 or det.shape[0] == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        d = np.hypot(pred[:, None, 0] - det[None, :, 0], pred[:, None, 1] - det[None, :, 1])
        d[d > self.config.gate] = np.inf
        ti: list[int] = []
        di: list[int] = []
        for _ in range(min(d.shape)):
            flat = int(np.argmin(d))
            i, j = divmod(flat, d.shape[1])
            if not math.isfinite(d[i, j]):
                break
            ti.append(i)
            di.append(j)
            d[i, :] = np.inf
            d[:, j] = np.inf
        return np.asarray(ti, dtype=np.int64), np.asarray(di, dtype=np.int64)

    def update(self, detections: Circles, stamp: float) -> Circles:
        """Associate ``detections`` (circles of one scan taken at ``stamp`` [s]) with the
        tracks, update them, and return the current tracks as circles."""
        cfg = self.config
        dt = 0.0 if self._t is None else stamp - self._t
        if dt < 0:
            raise ValueError(f"ObstacleTracker.update: stamp went back by {-dt:.3f} s")
        self._t = stamp
        pred = self._pos + self._vel * dt
        ti, di = self._associate(pred, detections.centres)
        pos = pred.copy()
        vel = self._vel.copy()
        if ti.size:
            res = detections.centres[di] - pred[ti]
            pos[ti] = pred[ti] + cfg.alpha * res
            if dt > 0:
                vel[ti] = self._vel[ti] + (cfg.beta / dt) * res
                speed = np.hypot(*vel[ti].T)
                over = speed > cfg.max_speed
                vel[ti[over]] *= (cfg.max_speed / speed[over])[:, None]
        seen = self._seen.copy()
        seen[ti] = stamp
        radius, safety = self._radius.copy(), self._safety.copy()
        radius[ti] = detections.radii[di]
        safety[ti] = detections.safety_radii[di]
        moving = self._moving.copy()
        if dt > 0 and ti.size:
            fast = np.hypot(*vel[ti].T) > cfg.moving_speed
            moving[ti] = np.where(fast, moving[ti] + 1, 0)
        travelled = np.hypot(*(pos - self._born).T) >= cfg.min_travel
        person = self._person | ((moving >= cfg.confirm) & travelled & (radius <= cfg.person_radius))
        became = person & ~self._person
        if became.any():
            log.debug("tracks %s classified as people", self._ids[became].tolist())
        alive = stamp - seen <= cfg.max_age
        new = np.ones(detections.centres.shape[0], dtype=bool)
        new[di] = False
        n_new = int(new.sum())
        ids_new = np.arange(self._next_id, self._next_id + n_new, dtype=np.int64)
        self._next_id += n_new
        self._pos = np.concatenate([pos[alive], detections.centres[new]])
        self._born = np.concatenate([self._born[alive], detections.centres[new]])
        self._vel = np.concatenate([vel[alive], np.zeros((n_new, 2))])
        self._radius = np.concatenate([radius[alive], detections.radii[new]])
        self._safety = np.concatenate([safety[alive], detections.safety_radii[new]])
        self._ids = np.concatenate([self._ids[alive], ids_new])
        self._seen = np.concatenate([seen[alive], np.full(n_new, stamp)])
        self._moving = np.concatenate([moving[alive], np.zeros(n_new, dtype=np.int64)])
        self._person = np.concatenate([person[alive], np.zeros(n_new, dtype=bool)])
        return self.circles()

    def circles(self) -> Circles:
        """The current tracks (positions at the last update's stamp; velocities of people
        only, zero for the rest)."""
        vel = np.where(self._person[:, None], self._vel, 0.0)
        return Circles(self._pos.copy(), self._radius.copy(), self._safety.copy(), vel,
                       self._ids.copy(), self._person.copy())

    def velocities(self) -> np.ndarray:
        """The filter's velocity estimates [m/s] (n, 2) of every track, people or not."""
        return self._vel.copy()
