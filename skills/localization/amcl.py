"""Adaptive Monte Carlo localisation (AMCL), optionally enhanced with laser reflectors.

The particle filter of Probabilistic Robotics chapter 8 as ROS ``amcl`` runs it, in numpy
over the whole particle set (no per-particle Python loop):

* prediction with the odometry motion model (:mod:`.motion`) once the robot has moved
  ``update_min_d`` [m] or turned ``update_min_a`` [rad] since the last update;
* correction with the likelihood-field model (:mod:`.likelihood`);
* ``w_slow`` / ``w_fast`` averages of the measurement likelihood (``recovery_alpha_slow``,
  ``recovery_alpha_fast``): when the short-term average falls below the long-term one,
  a share ``max(0, 1 - w_fast / w_slow)`` of the resampled set is drawn uniformly over the
  free map (recovery from a kidnapping). Off by default, as in ROS. With ROS's suggested
  0.001 / 0.1 it injects particles whenever a place explains the scan less well than the
  run's average, and the injected particles lower the next average further: with ROS's
  other defaults the plain filter in the sim lab ran at ``max_particles`` and lost
  itself; with ours it tracks as well and recovers most kidnappings in 4-15 s;
* low-variance resampling every ``resample_interval`` updates (only after motion);
* the particle count adapts with KLD sampling (Fox 2003): the fewest samples such that,
  with probability ``1 - kld_delta``, the KL divergence between the sampled and the true
  posterior stays below ``kld_err``, counted over histogram bins of ``kld_bin``
  (``(x [m], y [m], theta [rad])``), clamped to ``[min_particles, max_particles]``.
  ROS passes ``pf_z = 0.99`` where the formula wants the normal quantile (its comment
  says so); we use the quantile of ``1 - kld_delta`` (2.33 for 0.99).

With a :class:`~.reflectors.TriangleLibrary`, every scan in which at least three reflectors
are matched also gives a pose fix (:func:`~.reflectors.fix_from_scan`), and the weights
become ``omega = alpha * s * omega + beta * d`` (paper equation 6) with each of the two
terms normalised over the particle set first, so that ``alpha : beta`` is the share of
the posterior each carries (the paper gives no scale for omega, s and d; raw, the balance
would swing with the particle count and the spreads: with d's 3 cm spread, d outweighed
the scan by a factor of 1000 and the estimate followed each scan's noisy fix);
``inject_fraction`` of the resampled set is drawn around the fix (equation 7). Below three
matches the update is plain AMCL (the paper's algorithm 1, line 3).

Defaults: ROS's, except where the sim LoCoBot campaign (benchmarks/localization.py,
docs/localization.md) showed them far off for a Kobuki-class base with a 360 degree
lidar: ``min_particles`` 1000, updates every 5 cm / 0.1 rad, motion-model alphas 0.05
(:class:`~.motion.OdometryNoise`) and ``sigma_hit`` 0.1 m (:class:`~.likelihood.BeamModel`).

The estimate is the weighted mean of the heaviest cluster (particles within
``cluster_radius`` of the heaviest histogram bin), with its covariance; ``converged`` says
the position and heading spreads are below ``converged_xy`` and ``converged_theta``.
Frames: particles and the estimate are ``base_link`` in ``map``; odometry poses are
``base_link`` in ``odom``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from statistics import NormalDist

import numpy as np

from mmexec.drivers.geometry import se2_matrix
from mmexec.drivers.geometry import wrap_angle as wrap
from mmexec.drivers.interfaces import OccupancyGrid
from mmexec.skills.localization.likelihood import BeamModel, LikelihoodField
from mmexec.skills.localization.motion import OdometryNoise, odometry_step, sample_odometry_motion
from mmexec.skills.localization.reflectors import (
    ReflectorConfig,
    ReflectorFix,
    TriangleLibrary,
    fix_from_scan,
    orientation_score,
    position_weight,
)

__all__ = ["AmclConfig", "Estimate", "ParticleFilter", "kld_sample_count"]


@dataclass(frozen=True)
class AmclConfig:
    """Filter parameters (ROS names and defaults where ROS has them)."""

    min_particles: int = 1000
    max_particles: int = 5000
    kld_err: float = 0.01
    kld_delta: float = 0.01
    kld_bin: tuple[float, float, float] = (0.5, 0.5, math.radians(10.0))
    update_min_d: float = 0.05
    update_min_a: float = 0.1
    resample_interval: int = 1
    recovery_alpha_slow: float = 0.0
    recovery_alpha_fast: float = 0.0
    #: initial spread around a given pose: (sigma_xy [m], sigma_theta [rad])
    initial_sigma: tuple[float, float] = (0.25, 0.2)
    #: cluster radius of the estimate: (xy [m], theta [rad])
    cluster_radius: tuple[float, float] = (0.5, 0.5)
    converged_xy: float = 0.15
    converged_theta: float = 0.15
    odometry: OdometryNoise = field(default_factory=OdometryNoise)
    beams: BeamModel = field(default_factory=BeamModel)
    #: None: plain AMCL
    reflectors: ReflectorConfig | None = field(default_factory=ReflectorConfig)


@dataclass(frozen=True)
class Estimate:
    """The filter's pose ``(x, y, theta)`` of ``base_link`` in ``map``, its 3x3 covariance
    ``[m^2, m^2, rad^2]``, whether it has converged, and the particle count."""

    pose: np.ndarray
    covariance: np.ndarray
    converged: bool
    particles: int


def kld_sample_count(k: np.ndarray | int, err: float, z: float) -> np.ndarray:
    """KLD bound on the sample count for ``k`` occupied bins (Fox 2003, equation 12)."""
    k = np.maximum(np.asarray(k, dtype=np.float64), 2.0)
    a = 2.0 / (9.0 * (k - 1.0))
    return np.ceil((k - 1.0) / (2.0 * err) * (1.0 - a + np.sqrt(a) * z) ** 3)


class ParticleFilter:
    """AMCL on ``grid`` (a map in ``map``), with reflectors at ``reflectors`` (``(K, 2)``
    [m] in ``map``) when given and ``cfg.reflectors`` is set.

    ``mount``: the lidar pose ``(x, y, yaw)`` in ``base_link``. ``rng``: the only source
    of randomness (seed it for reproducible runs).
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        cfg: AmclConfig | None = None,
        *,
        reflectors: np.ndarray | None = None,
        mount: tuple[float, float, float] = (0.0, 0.0, 0.0),
        rng: np.random.Generator | None = None,
    ) -> None:
        self.cfg = cfg or AmclConfig()
        self.field = LikelihoodField(grid, self.cfg.beams)
        self.mount = mount
        self.rng = rng or np.random.default_rng()
        self.library = (
            TriangleLibrary(reflectors)
            if reflectors is not None and len(reflectors) >= 3 and self.cfg.reflectors is not None
            else None
        )
        free = np.argwhere(grid.data == 0)
        self._free_cells = free
        self._z = NormalDist().inv_cdf(1.0 - self.cfg.kld_delta)
        self.particles = np.zeros((0, 3))
        self.weights = np.zeros(0)
        self._odom: np.ndarray | None = None  # odometry pose at the last filter update
        self._w_slow = 0.0
        self._w_fast = 0.0
        self._updates = 0
        self._force = False
        #: the last reflector fix (None when the last scan matched fewer than three)
        self.last_fix: ReflectorFix | None = None
        #: the mean scan likelihood over the particles at the last update (what w_slow and
        #: w_fast average; 0 before the first update)
        self.last_likelihood = 0.0
        self._estimate: Estimate | None = None

    # ------------------------------------------------------------------ initialisation

    def initialise(self, pose: np.ndarray | tuple[float, float, float], sigma: tuple[float, float] | None = None) -> None:
        """Start from a Gaussian around ``pose`` (``(x, y, theta)`` in ``map``) with spread
        ``sigma = (xy [m], theta [rad])`` (default ``initial_sigma``)."""
        sxy, sth = sigma or self.cfg.initial_sigma
        n = max(self.cfg.min_particles, min(self.cfg.max_particles, 500))
        p = np.empty((n, 3))
        p[:, 0] = self.rng.normal(pose[0], sxy, n)
        p[:, 1] = self.rng.normal(pose[1], sxy, n)
        p[:, 2] = wrap(self.rng.normal(pose[2], sth, n))
        self._reset(p)

    def global_localisation(self) -> None:
        """Spread ``max_particles`` uniformly over the free map (ROS ``global_localization``)."""
        self._reset(self._uniform(self.cfg.max_particles))

    def _reset(self, particles: np.ndarray) -> None:
        self.particles = particles
        self.weights = np.full(len(particles), 1.0 / len(particles))
        self._w_slow = self._w_fast = 0.0
        self._estimate = None
        self._force = True  # the next scan updates, moved or not

    def _uniform(self, n: int) -> np.ndarray:
        if len(self._free_cells) == 0:
            raise ValueError("the map has no free cell to spread particles over")
        grid = self.field.grid
        cells = self._free_cells[self.rng.integers(0, len(self._free_cells), n)]
        res = grid.resolution
        gx = (cells[:, 1] + self.rng.random(n)) * res
        gy = (cells[:, 0] + self.rng.random(n)) * res
        o = grid.origin
        c, s = math.cos(o.theta), math.sin(o.theta)
        out = np.empty((n, 3))
        out[:, 0] = o.x + c * gx - s * gy
        out[:, 1] = o.y + s * gx + c * gy
        out[:, 2] = self.rng.uniform(-math.pi, math.pi, n)
        return out

    # ------------------------------------------------------------------ update

    def update(
        self,
        odom: np.ndarray | tuple[float, float, float],
        ranges: np.ndarray,
        angles: np.ndarray,
        range_max: float,
        intensities: np.ndarray | None = None,
    ) -> bool:
        """Feed one scan taken at odometry pose ``odom`` (``base_link`` in ``odom``).

        Returns True when the filter updated (enough motion since the last update, or
        the first scan after (re)initialisation). Call :meth:`initialise` or
        :meth:`global_localisation` first.
        """
        if len(self.particles) == 0:
            raise RuntimeError("the particle filter has no particles: call initialise() or global_localisation() first")
        odom = np.asarray(odom, dtype=np.float64)
        if self._odom is None:
            self._odom = odom
            self._force = True
        moved = self._moved(odom)
        if not (moved or self._force):
            return False
        if moved:
            self.particles = sample_odometry_motion(self.particles, self._odom, odom, self.cfg.odometry, self.rng)
        self._odom = odom
        self._correct(ranges, angles, range_max, intensities)
        self._updates += 1
        if moved and self._updates % self.cfg.resample_interval == 0:
            self._resample()
        self._force = False
        self._estimate = None
        return True

    def _moved(self, odom: np.ndarray) -> bool:
        """Whether odometry pose ``odom`` is ``update_min_d`` / ``update_min_a`` from the
        one at the last update."""
        assert self._odom is not None
        _, trans, _ = odometry_step(self._odom, odom)
        return trans >= self.cfg.update_min_d or abs(float(wrap(odom[2] - self._odom[2]))) >= self.cfg.update_min_a

    def wants_update(self, odom: np.ndarray | tuple[float, float, float]) -> bool:
        """Whether :meth:`update` at odometry pose ``odom`` would update the filter (so a
        caller can skip taking a scan it would ignore)."""
        return self._odom is None or self._force or self._moved(np.asarray(odom, dtype=np.float64))

    def _correct(self, ranges: np.ndarray, angles: np.ndarray, range_max: float, intensities: np.ndarray | None) -> None:
        r, a = self.field.beam_subset(np.asarray(ranges, dtype=np.float64), np.asarray(angles, dtype=np.float64), range_max)
        lik = self.field.scan_likelihood(self.particles, r, a, range_max, self.mount)
        w = self.weights * lik
        total = float(w.sum())
        # w_slow / w_fast track the average measurement likelihood (before the reflectors,
        # which are a different measurement: a kidnapped robot must still look unlikely).
        w_avg = float(np.mean(lik))
        self.last_likelihood = w_avg
        if self._w_slow == 0.0:
            self._w_slow = self._w_fast = w_avg
        else:
            self._w_slow += self.cfg.recovery_alpha_slow * (w_avg - self._w_slow)
            self._w_fast += self.cfg.recovery_alpha_fast * (w_avg - self._w_fast)
        self.last_fix = None
        rc = self.cfg.reflectors
        if self.library is not None and rc is not None:
            self.last_fix = fix_from_scan(ranges, angles, intensities, self.library, rc, self.mount)
        if self.last_fix is not None and rc is not None:
            fix = self.last_fix
            w = w / total if total > 0 else np.full(len(w), 1.0 / len(w))
            centres = self.library.reflectors[list(fix.ids)] if self.library is not None else np.zeros((0, 2))
            bearings = np.array([d.bearing for d in fix.detections])
            s = orientation_score(self.particles, centres, bearings, rc, self.mount)
            d = position_weight(self.particles, fix.pose, rc)
            w = rc.alpha * _normalised(s * w) + rc.beta * _normalised(d)
            total = float(w.sum())
        self.weights = w / total if total > 0 else np.full(len(w), 1.0 / len(w))

    def _resample(self) -> None:
        cfg = self.cfg
        n_draw = cfg.max_particles
        # Low-variance (systematic) resampling of n_draw candidates, in random order so
        # that any prefix is itself a fair sample for the KLD count.
        cum = np.cumsum(self.weights)
        cum[-1] = 1.0
        u = (self.rng.random() + np.arange(n_draw)) / n_draw
        idx = np.searchsorted(cum, u)
        cand = self.particles[self.rng.permutation(idx)]
        # Random injection: uniform recovery (w_fast / w_slow) and particles around a fix.
        p_random = max(0.0, 1.0 - self._w_fast / self._w_slow) if self._w_slow > 0 else 0.0
        inject = self.rng.random(n_draw) < p_random
        if inject.any():
            cand[inject] = self._uniform(int(inject.sum()))
        fix, rc = self.last_fix, cfg.reflectors
        if fix is not None and rc is not None and rc.inject_fraction > 0:
            m = round(rc.inject_fraction * n_draw)
            if m:
                at = self.rng.choice(n_draw, m, replace=False)
                cand[at, 0] = self.rng.normal(fix.pose[0], rc.sigma_xy, m)
                cand[at, 1] = self.rng.normal(fix.pose[1], rc.sigma_xy, m)
                cand[at, 2] = wrap(self.rng.normal(fix.pose[2], rc.sigma_theta, m))
        # KLD: the fewest leading candidates whose bin count says "enough".
        bins = self._bins(cand)
        _, first = np.unique(bins, return_index=True)
        is_new = np.zeros(n_draw, dtype=np.int64)
        is_new[first] = 1
        k = np.cumsum(is_new)
        need = np.clip(kld_sample_count(k, cfg.kld_err, self._z), cfg.min_particles, cfg.max_particles)
        ok = np.flatnonzero(np.arange(1, n_draw + 1) >= need)
        n = int(ok[0]) + 1 if len(ok) else n_draw
        self.particles = cand[:n].copy()
        self.weights = np.full(n, 1.0 / n)

    def _bins(self, p: np.ndarray) -> np.ndarray:
        bx, by, bt = self.cfg.kld_bin
        ix = np.floor(p[:, 0] / bx).astype(np.int64)
        iy = np.floor(p[:, 1] / by).astype(np.int64)
        it = np.floor((p[:, 2] + math.pi) / bt).astype(np.int64)
        return (ix * 100003 + iy) * 1009 + it

    # ------------------------------------------------------------------ outputs

    def estimate(self) -> Estimate:
        """The pose estimate of the heaviest cluster, its covariance and convergence."""
        if self._estimate is not None:
            return self._estimate
        p, w = self.particles, self.weights
        bins = self._bins(p)
        uniq, inv = np.unique(bins, return_inverse=True)
        heavy = int(np.argmax(np.bincount(inv, weights=w, minlength=len(uniq))))
        sel = inv == heavy
        seed = self._mean(p[sel], w[sel])
        rxy, rth = self.cfg.cluster_radius
        near = (np.hypot(p[:, 0] - seed[0], p[:, 1] - seed[1]) <= rxy) & (np.abs(wrap(p[:, 2] - seed[2])) <= rth)
        pc, wc = p[near], w[near]
        mean = self._mean(pc, wc)
        wn = wc / wc.sum()
        dev = np.stack([pc[:, 0] - mean[0], pc[:, 1] - mean[1], wrap(pc[:, 2] - mean[2])], axis=1)
        cov = (dev * wn[:, None]).T @ dev
        converged = (
            math.sqrt(max(cov[0, 0], cov[1, 1])) <= self.cfg.converged_xy
            and math.sqrt(cov[2, 2]) <= self.cfg.converged_theta
            and float(wc.sum()) >= 0.5
        )
        self._estimate = Estimate(mean, cov, converged, len(p))
        return self._estimate

    @staticmethod
    def _mean(p: np.ndarray, w: np.ndarray) -> np.ndarray:
        wn = w / w.sum()
        th = math.atan2(float(np.sum(wn * np.sin(p[:, 2]))), float(np.sum(wn * np.cos(p[:, 2]))))
        return np.array([float(np.sum(wn * p[:, 0])), float(np.sum(wn * p[:, 1])), th])

    def map_to_odom(self) -> np.ndarray:
        """``T_map_odom`` (3x3 homogeneous, planar): the correction that maps the raw
        odometry pose at the last update onto the estimate."""
        if self._odom is None:
            return np.eye(3)
        est = self.estimate().pose
        return se2_matrix(*map(float, est)) @ np.linalg.inv(se2_matrix(*map(float, self._odom)))


def _normalised(w: np.ndarray) -> np.ndarray:
    """``w`` scaled to sum 1 (all zeros when it sums to 0: that term then carries nothing)."""
    total = float(w.sum())
    return w / total if total > 0 else np.zeros_like(w)
