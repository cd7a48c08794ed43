"""The localiser in the capability layer: AMCL (:class:`~.amcl.ParticleFilter`) fed with
the robot's lidar scans and base odometry, its ``map -> odom`` correction applied to
every pose a skill reads in ``map``.

The executive wraps a built robot with :func:`localise_robot` when the run config has a
``localization:`` section with ``enabled: true`` (:class:`LocalizationSettings`; every
backend alike, one implementation). The wrapped robot is the backend's own, except:

* ``base`` is a :class:`LocalizingBase`: ``state().pose`` is ``T_map_odom`` times the
  backend's odometry pose; ``state().covariance`` is the filter's covariance and
  ``state().localised`` whether it has converged. Commands go to the backend's base
  unchanged; :meth:`LocalizingBase.odometry` is the raw odometry state.
* ``camera`` is a :class:`LocalizedCamera`: every backend stamps a frame with its base's
  odometry pose (``T_map_base``); the wrapper applies the same correction, so marker
  poses land in ``map``.
* ``spin(period)`` runs one :meth:`Localizer.step` (at most one filter update, 3 ms
  median with 1000 particles) and then the backend's spin. On the real robot the spin
  sleeps to the next period boundary, so the update takes its time out of the wait, not
  out of the tick; on the sim the update runs at a fixed point of the stepped clock, so a
  seed reproduces a run. No thread: nothing to lock, and a tick never waits for the
  filter.

Every other attribute (``truth`` on the sim, ``head``, ...) is the backend robot's.

Frames: ``odom`` is the frame the base's odometry integrates in (the backend's ``map``
pose before this wrapper: it starts at the start pose); ``map`` the map's. The filter's
particles are ``base_link`` in ``map``; scans are in the lidar frame, mounted at
``scan.T_base_lidar``.

Start: ``start: odometry`` spreads the particles around the odometry pose at the first
scan (``initial_sigma``; the odometry starts where the config says the robot starts), so
the robot is localised at once when it starts where it should; ``start: global`` spreads
them over the whole free map (not localised until the filter converges: run the
``localize`` skill).

Kidnap while standing: AMCL updates only after motion (as ROS), so a robot moved while it
stands would drive off with a wrong pose. Every ``still_check`` seconds at rest, when
the map has reflectors, the localiser compares the scan's reflector fix
(:func:`~.reflectors.fix_from_scan`) with its estimate; two fixes in a row that agree
with each other and differ from the estimate by more than ``lost_distance`` /
``lost_angle`` re-seed the filter around the fix (the paper's particle injection, done
at rest). While the base moves, the filter's own injection around each fix recovers.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from mmexec.config.yamlload import Mark, Problems, bind
from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import (
    Base,
    BaseState,
    Camera,
    CameraFrame,
    CameraIntrinsics,
    Clock,
    LaserScan,
    Lidar,
    OccupancyGrid,
    Pose2D,
    Robot,
)
from mmexec.skills.localization.amcl import AmclConfig, Estimate, ParticleFilter
from mmexec.skills.localization.likelihood import BeamModel
from mmexec.skills.localization.motion import OdometryNoise
from mmexec.skills.localization.reflectors import (
    ReflectorConfig,
    ReflectorFix,
    fix_from_scan,
)

__all__ = [
    "LocalizationSettings",
    "LocalizedCamera",
    "LocalizedRobot",
    "Localizer",
    "LocalizingBase",
    "localise_robot",
    "parse_section",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LocalizationSettings:
    """The run config's ``localization:`` section (docs/localization.md, "In the
    executive"). Units: m, rad, s of clock time. The filter's other parameters keep
    :class:`~.amcl.AmclConfig`'s defaults."""

    #: run the localiser (false: the odometry is the map pose, as without the section)
    enabled: bool = True
    #: use the map's reflector posts (false: plain AMCL)
    reflectors: bool = True
    #: where the particles start: around the odometry pose, or over the whole free map
    start: Literal["odometry", "global"] = "odometry"
    #: spread of ``start: odometry`` (sigma_xy [m], sigma_theta [rad]); below the
    #: convergence thresholds, so a robot that starts where it should is localised at once
    initial_sigma: tuple[float, float] = (0.1, 0.1)
    #: least clock time between two scans fed to the filter [s] (the A2 turns at 10 Hz)
    scan_period: float = 0.1
    min_particles: int = 1000
    max_particles: int = 5000
    #: motion before a filter update [m], [rad]
    update_min_d: float = 0.05
    update_min_a: float = 0.1
    #: motion model alpha1..alpha4 (ROS odom_alpha1..4)
    odom_alpha: tuple[float, float, float, float] = (0.05, 0.05, 0.05, 0.05)
    #: likelihood field: spread of a beam end point around the nearest obstacle [m]
    sigma_hit: float = 0.1
    #: beams used per scan
    max_beams: int = 60
    #: converged (``localised``) when the cluster's spreads are below these [m], [rad]
    converged_xy: float = 0.15
    converged_theta: float = 0.15
    #: ROS's w_slow / w_fast random-particle recovery (0, 0: off)
    recovery_alpha_slow: float = 0.0
    recovery_alpha_fast: float = 0.0
    #: at rest, compare a reflector fix with the estimate this often [s] (0: never)
    still_check: float = 1.0
    #: a fix this far from the estimate (twice in a row) re-seeds the filter [m], [rad]
    lost_distance: float = 0.3
    lost_angle: float = 0.3
    #: share of each filter update's change of the pose estimate applied to the published
    #: correction (1: all at once, ROS's behaviour); a change beyond ``jump`` is applied
    #: at once. Smoothing keeps the pose locally as consistent as the odometry: a marker
    #: seen at 0.8 m and grasped from 0.58 m must agree to a few mm, less than AMCL's
    #: update-to-update jitter
    smoothing: float = 0.3
    #: a change of the estimate beyond this is applied at once (a re-localisation) [m], [rad]
    jump: tuple[float, float] = (0.1, 0.1)
    #: lost (not ``localised``) when, averaged over the last few scans, fewer than this
    #: share of the beams end within ``fit_distance`` [m] of a mapped obstacle at the
    #: estimate; localised again above it plus 0.15 (and converged)
    lost_fit: float = 0.35
    fit_distance: float = 0.15

    def validate(self) -> list[str]:
        out = []
        if not 1 <= self.min_particles <= self.max_particles:
            out.append(f"need 1 <= min_particles <= max_particles, got {self.min_particles}, {self.max_particles}")
        positive = {"scan_period": self.scan_period, "sigma_hit": self.sigma_hit, "converged_xy": self.converged_xy,
                    "converged_theta": self.converged_theta, "lost_distance": self.lost_distance,
                    "lost_angle": self.lost_angle, "initial_sigma": min(self.initial_sigma),
                    "fit_distance": self.fit_distance}
        out += [f"{k} must be > 0, got {v:g}" for k, v in positive.items() if not v > 0]
        non_negative = {"update_min_d": self.update_min_d, "update_min_a": self.update_min_a,
                        "still_check": self.still_check, "odom_alpha": min(self.odom_alpha),
                        "recovery_alpha_slow": self.recovery_alpha_slow,
                        "recovery_alpha_fast": self.recovery_alpha_fast}
        out += [f"{k} must be >= 0, got {v:g}" for k, v in non_negative.items() if not v >= 0]
        if not 0 < self.smoothing <= 1:
            out.append(f"smoothing must be in (0, 1], got {self.smoothing:g}")
        if not min(self.jump) > 0:
            out.append(f"jump must be > 0, got {list(self.jump)}")
        if not 0 <= self.lost_fit < 0.85:
            out.append(f"lost_fit must be in [0, 0.85), got {self.lost_fit:g}")
        if self.max_beams < 2:
            out.append(f"max_beams must be >= 2, got {self.max_beams}")
        return out

    def amcl(self, reflectors: ReflectorConfig | None) -> AmclConfig:
        """The filter's configuration (``reflectors``: None for plain AMCL)."""
        a1, a2, a3, a4 = self.odom_alpha
        return AmclConfig(
            min_particles=self.min_particles, max_particles=self.max_particles, update_min_d=self.update_min_d,
            update_min_a=self.update_min_a, recovery_alpha_slow=self.recovery_alpha_slow,
            recovery_alpha_fast=self.recovery_alpha_fast, initial_sigma=self.initial_sigma,
            converged_xy=self.converged_xy, converged_theta=self.converged_theta,
            odometry=OdometryNoise(a1, a2, a3, a4),
            beams=replace(BeamModel(), sigma_hit=self.sigma_hit, max_beams=self.max_beams),
            reflectors=reflectors,
        )


def parse_section(section: Any, mark: Mark) -> LocalizationSettings | None:
    """Bind the run config's ``localization:`` section (None: absent); InputError with
    every problem ``FILE:LINE:COL: localization.KEY: ...``."""
    if section is None:
        return None
    problems = Problems()
    out = bind(LocalizationSettings, section, getattr(section, "mark", mark), "localization", problems)
    problems.raise_if_any()
    assert isinstance(out, LocalizationSettings)
    return out


# --------------------------------------------------------------------------- the localiser


@dataclass(frozen=True)
class _Snapshot:
    """What the wrapped base reports, replaced whole after each update (``T``: 3x3
    ``T_map_odom``)."""

    T: np.ndarray = field(default_factory=lambda: np.eye(3))
    covariance: tuple[tuple[float, float, float], ...] | None = None
    localised: bool = True


def _planar(pose: Pose2D) -> np.ndarray:
    c, s = math.cos(pose.theta), math.sin(pose.theta)
    return np.array([[c, -s, pose.x], [s, c, pose.y], [0.0, 0.0, 1.0]])


def _apply(T: np.ndarray, pose: Pose2D) -> Pose2D:
    """``T`` (3x3 planar) times ``pose``."""
    x = T[0, 0] * pose.x + T[0, 1] * pose.y + T[0, 2]
    y = T[1, 0] * pose.x + T[1, 1] * pose.y + T[1, 2]
    return Pose2D(float(x), float(y), float(wrap_angle(pose.theta + math.atan2(T[1, 0], T[0, 0]))))


class Localizer:
    """AMCL on ``grid`` (its :attr:`~mmexec.drivers.interfaces.OccupancyGrid.reflectors`
    as landmarks unless ``settings.reflectors`` is false), fed by ``lidar`` and the raw
    ``base`` (odometry). Call :meth:`step` once per control period; read
    :meth:`snapshot`. ``rng`` is the filter's only randomness."""

    #: odometry history kept to find the odometry pose at a scan's stamp [s]
    HISTORY = 2.0

    def __init__(self, base: Base, lidar: Lidar, grid: OccupancyGrid, clock: Clock, settings: LocalizationSettings,
                 rng: np.random.Generator | None = None) -> None:
        self.base, self.lidar, self.grid, self.clock, self.settings = base, lidar, grid, clock, settings
        self.rng = rng or np.random.default_rng()
        posts = grid.reflectors if settings.reflectors else ()
        self.reflectors = np.array([p.position for p in posts], dtype=np.float64).reshape(-1, 2)
        radii = sorted({p.radius for p in posts})
        if len(radii) > 1:
            log.warning("localization: the map's reflector posts have different radii %s m; fitting %.3f m",
                        radii, radii[0])
        # three posts at least for a fix; fewer: plain AMCL
        self.amcl = settings.amcl(ReflectorConfig(post_radius=radii[0]) if len(posts) >= 3 else None)
        self.filter: ParticleFilter | None = None  # built at the first scan (it needs the lidar mount)
        self._global = settings.start == "global"
        self._snap = _Snapshot(localised=not self._global)
        self._history: deque[tuple[float, Pose2D]] = deque()
        self._last_scan = -math.inf  # clock time of the last scan taken
        self._last_stamp = -math.inf  # stamp of the last scan used
        self._last_check = -math.inf
        self._last_fix: ReflectorFix | None = None
        self.updates = 0  #: filter updates run
        self.reseeds = 0  #: re-seeds around a reflector fix at rest (kidnaps caught standing)
        #: share of the beams the map explains at the estimate, averaged over the last scans
        self.fit = 1.0
        self.lost = False  #: the scans stopped matching the map at the estimate (see ``lost_fit``)

    # ------------------------------------------------------------------ outputs

    def snapshot(self) -> _Snapshot:
        """The current correction, covariance and flag (never blocks)."""
        return self._snap

    def estimate(self) -> Estimate | None:
        """The filter's estimate (None before the first scan)."""
        return self.filter.estimate() if self.filter is not None else None

    # ------------------------------------------------------------------ requests

    def global_localisation(self) -> None:
        """Spread the particles over the whole free map (the ``localize`` skill); not
        localised until the filter converges again."""
        if self.filter is None:
            self._global = True
        else:
            self.filter.global_localisation()
        self._snap = replace(self._snap, localised=False)
        self.lost, self.fit = False, 1.0

    # ------------------------------------------------------------------ the step

    def step(self) -> bool:
        """Feed the newest scan when one is due and the filter wants it; returns True when
        the filter updated. Never blocks: at most one update (ms)."""
        now = self.clock.now()
        raw = self.base.state()
        self._history.append((raw.stamp, raw.pose))
        while len(self._history) > 2 and self._history[0][0] < raw.stamp - self.HISTORY:
            self._history.popleft()
        if now - self._last_scan < self.settings.scan_period - 1e-9:
            return False
        pf = self.filter
        moved = pf is None or pf.wants_update(_arr(raw.pose))
        check = (not moved and self.settings.still_check > 0 and pf is not None and pf.library is not None
                 and now - self._last_check >= self.settings.still_check)
        if not (moved or check):
            return False
        self._last_scan = now
        scan = self.lidar.scan()
        if scan is None or scan.stamp <= self._last_stamp:
            return False
        self._last_stamp = scan.stamp
        odom = self._odometry_at(scan.stamp, raw.pose)
        if self.filter is None:
            self._start(scan, odom)
        assert self.filter is not None
        if check:
            self._last_check = now
            self._check_at_rest(scan, odom)
        ran = self.filter.update(_arr(odom), scan.ranges, scan.angles, scan.range_max, scan.intensities)
        if ran:
            self.updates += 1
        self._watch_fit(scan, odom)
        if ran:
            self._publish(odom)
        else:  # a rest check: the flag may change, the correction does not (the pose holds still)
            self._snap = replace(self._snap, localised=bool(self.filter.estimate().converged) and not self.lost)
        return ran

    def _start(self, scan: LaserScan, odom: Pose2D) -> None:
        T = scan.T_base_lidar
        mount = (float(T[0, 3]), float(T[1, 3]), math.atan2(T[1, 0], T[0, 0]))
        self.filter = ParticleFilter(self.grid, self.amcl, reflectors=self.reflectors if len(self.reflectors) else None,
                                     mount=mount, rng=self.rng)
        if self._global:
            self.filter.global_localisation()
        else:
            self.filter.initialise(_arr(odom))
        log.info("localization: started (%s, %d reflectors, %s)", self.settings.start, len(self.reflectors),
                 "reflector AMCL" if self.filter.library is not None else "plain AMCL")

    def _check_at_rest(self, scan: LaserScan, odom: Pose2D) -> None:
        """Re-seed the filter around the reflector fix when two in a row agree with each
        other and not with the estimate (a kidnap while standing)."""
        pf = self.filter
        assert pf is not None and pf.library is not None and pf.cfg.reflectors is not None
        fix = fix_from_scan(scan.ranges, scan.angles, scan.intensities, pf.library, pf.cfg.reflectors, pf.mount)
        last, self._last_fix = self._last_fix, fix
        if fix is None or last is None:
            return
        s = self.settings
        if math.hypot(*(fix.pose[:2] - last.pose[:2])) > 0.1 or abs(wrap_angle(fix.pose[2] - last.pose[2])) > 0.1:
            return  # the two fixes disagree: trust neither
        est = _apply(pf.map_to_odom(), odom)
        off = math.hypot(fix.pose[0] - est.x, fix.pose[1] - est.y)
        turn = abs(wrap_angle(float(fix.pose[2]) - est.theta))
        if off > s.lost_distance or turn > s.lost_angle:
            at_fix = self._scan_fit(scan, Pose2D(*map(float, fix.pose)))
            at_est = self._scan_fit(scan, est)
            if at_fix is not None and at_est is not None and at_fix <= at_est:
                # a wrong triangle (people hiding posts, a bright body taken for one):
                # the scan fits the map no better there than at the estimate
                log.info("localization: a reflector fix %.2f m / %.2f rad from the estimate, but the scan fits the "
                         "map no better there (%.0f %% against %.0f %%): not re-seeding", off, turn, 100 * at_fix,
                         100 * at_est)
                return
            log.warning("localization: the reflectors put the base %.2f m / %.2f rad from the estimate while it "
                        "stands; re-seeding the filter at (%.2f, %.2f, %.2f)", off, turn, *map(float, fix.pose))
            pf.initialise(fix.pose, (s.initial_sigma[0], s.initial_sigma[1]))
            self.reseeds += 1
            self._last_fix = None

    def _scan_fit(self, scan: LaserScan, pose: Pose2D) -> float | None:
        """The share of the scan's beams the map explains (within ``fit_distance``) with
        the base at map ``pose``; None with too few returns to judge."""
        pf = self.filter
        assert pf is not None
        r, a = pf.field.beam_subset(np.asarray(scan.ranges, dtype=np.float64),
                                    np.asarray(scan.angles, dtype=np.float64), scan.range_max)
        if len(r) < 10:
            return None  # too few returns to judge (a dropout, an open space)
        mx, my, myaw = pf.mount
        bx, by = mx + r * np.cos(a + myaw), my + r * np.sin(a + myaw)
        c, s = math.cos(pose.theta), math.sin(pose.theta)
        d = pf.field.distance_at(pose.x + c * bx - s * by, pose.y + s * bx + c * by)
        return float(np.mean(d <= self.settings.fit_distance))

    def _watch_fit(self, scan: LaserScan, odom: Pose2D) -> None:
        """Average the share of beams the map explains at the estimate (:attr:`fit`) and
        set :attr:`lost` below ``lost_fit`` (clear it above ``lost_fit + 0.15``)."""
        pf = self.filter
        assert pf is not None
        est = _apply(pf.map_to_odom(), odom)
        share = self._scan_fit(scan, est)
        if share is None:
            return
        self.fit = 0.5 * self.fit + 0.5 * share
        lost_fit = self.settings.lost_fit
        if not self.lost and self.fit < lost_fit:
            self.lost = True
            log.warning("localization: lost: only %.0f %% of the beams match the map at the estimate "
                        "(%.2f, %.2f, %.2f)", 100 * self.fit, est.x, est.y, est.theta)
        elif self.lost and self.fit >= lost_fit + 0.15:
            self.lost = False
            log.info("localization: the scans match the map again (%.0f %%)", 100 * self.fit)

    def _odometry_at(self, stamp: float, now: Pose2D) -> Pose2D:
        """The odometry pose at ``stamp`` [clock s], interpolated in the history (the
        newest pose when the stamp is not older than it)."""
        h = self._history
        if not h or stamp >= h[-1][0]:
            return now
        if stamp <= h[0][0]:
            return h[0][1]
        for (t0, p0), (t1, p1) in zip(list(h)[:-1], list(h)[1:]):
            if t0 <= stamp <= t1:
                a = 0.0 if t1 <= t0 else (stamp - t0) / (t1 - t0)
                return Pose2D(p0.x + a * (p1.x - p0.x), p0.y + a * (p1.y - p0.y),
                              float(wrap_angle(p0.theta + a * wrap_angle(p1.theta - p0.theta))))
        return now

    def _publish(self, odom: Pose2D) -> None:
        """Publish the filter's correction, moved ``smoothing`` of the way from the last
        published one (all the way beyond ``jump``, or while not localised)."""
        pf = self.filter
        assert pf is not None
        est = pf.estimate()
        cov = tuple(tuple(float(v) for v in row) for row in est.covariance)
        localised = bool(est.converged) and not self.lost
        T = pf.map_to_odom()
        g = self.settings.smoothing
        if g < 1 and localised and self._snap.localised:
            new, old = _apply(T, odom), _apply(self._snap.T, odom)
            dth = float(wrap_angle(new.theta - old.theta))
            if new.distance_to(old) <= self.settings.jump[0] and abs(dth) <= self.settings.jump[1]:
                mid = Pose2D(old.x + g * (new.x - old.x), old.y + g * (new.y - old.y), old.theta + g * dth)
                T = _planar(mid) @ np.linalg.inv(_planar(odom))
        self._snap = _Snapshot(T=T, covariance=cov, localised=localised)  # type: ignore[arg-type]


def _arr(pose: Pose2D) -> np.ndarray:
    return np.array([pose.x, pose.y, pose.theta])


# --------------------------------------------------------------------------- the wrappers


class LocalizingBase(Base):
    """The backend's base with its pose in ``map`` corrected by the :class:`Localizer`
    (module doc). Commands and faults are the backend base's; any other attribute of it
    (e.g. the sim's ``reset_estimate``) is reached through this object."""

    def __init__(self, inner: Base, localizer: Localizer) -> None:
        self.inner = inner
        self.localizer = localizer
        for k in ("max_linear", "max_angular", "max_linear_accel", "max_angular_accel", "radius", "command_timeout"):
            setattr(self, k, getattr(inner, k))

    def state(self) -> BaseState:
        raw = self.inner.state()
        snap = self.localizer.snapshot()
        return replace(raw, pose=_apply(snap.T, raw.pose), covariance=snap.covariance, localised=snap.localised)

    def odometry(self) -> BaseState:
        """The backend's own state: the raw odometry pose (in ``odom``)."""
        return self.inner.state()

    def set_velocity(self, v: float, w: float) -> None:
        self.inner.set_velocity(v, w)

    def stop(self) -> None:
        self.inner.stop()

    def __getattr__(self, name: str) -> Any:
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)


class LocalizedCamera(Camera):
    """The backend's camera with each frame's ``T_map_base`` corrected by the localiser
    (the backend stamps its base's odometry pose)."""

    def __init__(self, inner: Camera, localizer: Localizer) -> None:
        self.inner = inner
        self.localizer = localizer

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self.inner.intrinsics

    def pose_in_base(self) -> np.ndarray:
        return self.inner.pose_in_base()

    def frame(self) -> CameraFrame | None:
        f = self.inner.frame()
        if f is None:
            return None
        T = self.localizer.snapshot().T
        C = np.eye(4)
        C[:2, :2] = T[:2, :2]
        C[:2, 3] = T[:2, 2]
        return replace(f, T_map_base=C @ np.asarray(f.T_map_base, dtype=np.float64))

    def __getattr__(self, name: str) -> Any:
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)


class LocalizedRobot(Robot):
    """The backend's robot with a :class:`LocalizingBase` and a :class:`LocalizedCamera`;
    ``spin`` steps the localiser first (module doc). Everything else is the backend
    robot's."""

    def __init__(self, inner: Robot, localizer: Localizer) -> None:
        self.inner = inner
        self.localizer = localizer
        for name in _robot_attributes():
            if hasattr(inner, name):
                setattr(self, name, getattr(inner, name))
        assert inner.base is not None
        self.base = LocalizingBase(inner.base, localizer)
        if inner.camera is not None:
            self.camera = LocalizedCamera(inner.camera, localizer)

    def spin(self, period: float) -> None:
        self.localizer.step()
        self.inner.spin(period)

    def safe_stop(self) -> None:
        self.inner.safe_stop()

    def close(self) -> None:
        self.inner.close()

    def __getattr__(self, name: str) -> Any:
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)


def _robot_attributes() -> tuple[str, ...]:
    """The attributes the capability contract gives a :class:`Robot` (its annotations)."""
    names: list[str] = []
    for cls in reversed(Robot.__mro__):
        names += [n for n in getattr(cls, "__annotations__", {}) if n not in names]
    return tuple(names)


def localise_robot(robot: Robot, settings: LocalizationSettings, *, seed: int | None = None) -> Robot:
    """``robot`` wrapped with a localiser (:class:`LocalizedRobot`), or ``robot`` itself
    when ``settings.enabled`` is false. ValueError naming what is missing when the robot
    has no base, no lidar or no map (the executive reports it at the config's
    ``localization:``)."""
    if not settings.enabled:
        return robot
    missing = [what for what, have in (("a base", robot.base), ("a lidar", robot.lidar),
                                       ("a map (occupancy grid)", robot.occupancy)) if have is None]
    if missing:
        raise ValueError(f"the localiser needs {' and '.join(missing)}, and robot {robot.name!r} has none "
                         "(set localization.enabled: false)")
    assert robot.base is not None and robot.lidar is not None and robot.occupancy is not None
    rng = np.random.default_rng(None if seed is None else [seed, 11])
    return LocalizedRobot(robot, Localizer(robot.base, robot.lidar, robot.occupancy, robot.clock, settings, rng))
