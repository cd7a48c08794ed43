"""The local navigation tick: lidar -> rolling costmap and tracked circles -> DWA -> CLF-CBF.

:class:`LocalPlanner` composes the algorithm layer for a skill to call once per control
tick (it never blocks, never reads a clock and never talks to a device):

1. with a new scan: :func:`~mmexec.skills.navigation.obstacles.scan_to_map`, the rolling
   costmap's clearing and marking (which also says which hits are not the static map),
   clusters and circles of those hits, and the tracker (velocities, people);
2. the social speed scale from the nearest person caps the forward speed;
3. the DWA picks ``u_ref`` on the costmap and the circles, their safety radii grown by the
   filter's look-ahead ``l`` (the zone the filter guards; a DWA that planned into it
   would only be stopped by the filter), people moved at their tracked velocity;
4. the CLF-CBF filter makes ``u_ref`` safe against *every* circle, tracking the pose the
   DWA's rollout reaches ``reference_time`` seconds ahead. It may slow the base and steer
   it, but never drive it faster than the DWA's command: the filter sees only the
   circles, and a faster command (fleeing someone who walks up from behind) is one the
   costmap never checked; when slowing and steering cannot keep every barrier, it brakes.

The caller acts on the DWA status and ``path_blocked`` (re-plan globally on
:meth:`LocalPlanner.replan_grid`; recover when ``STUCK``).
:func:`mmexec.skills.navigation.synthetic.run_closed_loop` shows the whole loop.
Frames: ``map``; m, rad, s.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from mmexec.drivers.interfaces import LaserScan, OccupancyGrid, Pose2D
from mmexec.skills.navigation.cbf import CbfConfig, CbfFilter, CbfResult
from mmexec.skills.navigation.checks import checked
from mmexec.skills.navigation.costmap import CostmapConfig, RollingCostmap
from mmexec.skills.navigation.dwa import DwaConfig, DwaPlanner, DwaResult, DwaStatus
from mmexec.skills.navigation.limits import LOCOBOT_KOBUKI, BaseLimits
from mmexec.skills.navigation.obstacles import (
    Circles,
    ObstacleConfig,
    detect_obstacles,
    scan_to_map,
)
from mmexec.skills.navigation.social import SocialConfig, speed_scale
from mmexec.skills.navigation.tracks import ObstacleTracker, TrackingConfig

__all__ = ["LocalCommand", "LocalPlanner", "LocalPlannerConfig"]


@dataclass(frozen=True)
class LocalPlannerConfig:
    """The layers' configurations, which must agree on the base (``limits``) and the
    safety ``margin`` [m]: build with :meth:`for_base`. ``reference_time`` [s] picks the
    CLF reference on the DWA rollout; ``use_cbf`` False passes the DWA command through
    unfiltered (for comparisons only)."""

    limits: BaseLimits = LOCOBOT_KOBUKI
    margin: float = 0.05
    costmap: CostmapConfig = field(default_factory=CostmapConfig)
    obstacles: ObstacleConfig = field(default_factory=ObstacleConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    social: SocialConfig = field(default_factory=SocialConfig)
    dwa: DwaConfig = field(default_factory=DwaConfig)
    cbf: CbfConfig = field(default_factory=CbfConfig)
    reference_time: float = 0.5
    use_cbf: bool = True

    @classmethod
    def for_base(cls, limits: BaseLimits, margin: float = 0.05, *, costmap: CostmapConfig | None = None,
                 obstacles: ObstacleConfig | None = None, tracking: TrackingConfig | None = None,
                 social: SocialConfig | None = None, dwa: DwaConfig | None = None, cbf: CbfConfig | None = None,
                 reference_time: float = 0.5, use_cbf: bool = True) -> LocalPlannerConfig:
        """A consistent configuration for the base ``limits`` and ``margin`` [m]: the
        layers given (defaults otherwise) get the base radius, limits and margin written in."""
        soc = replace(social or SocialConfig(), robot_radius=limits.radius)
        return cls(
            limits=limits,
            margin=margin,
            costmap=costmap or CostmapConfig(),
            obstacles=replace(obstacles or ObstacleConfig(), robot_radius=limits.radius, margin=margin),
            tracking=tracking or TrackingConfig(),
            social=soc,
            dwa=replace(dwa or DwaConfig(), limits=limits, social=soc),
            cbf=replace(cbf or CbfConfig(), limits=limits),
            reference_time=reference_time,
            use_cbf=use_cbf,
        )

    def validate(self) -> list[str]:
        errs = (self.limits.validate() + self.costmap.validate() + self.obstacles.validate()
                + self.tracking.validate() + self.social.validate() + self.dwa.validate() + self.cbf.validate())
        r = self.limits.radius
        if self.obstacles.robot_radius != r or self.social.robot_radius != r:
            errs.append("obstacles.robot_radius and social.robot_radius must equal limits.radius (use for_base)")
        if self.obstacles.margin != self.margin:
            errs.append("obstacles.margin must equal margin (use for_base)")
        if self.dwa.limits != self.limits or self.cbf.limits != self.limits:
            errs.append("dwa.limits and cbf.limits must equal limits (use for_base)")
        if not self.reference_time > 0:
            errs.append(f"reference_time: must be > 0 s, got {self.reference_time}")
        return errs


@dataclass(frozen=True)
class LocalCommand:
    """One tick: the command ``(v, w)`` to send [m/s, rad/s]; the DWA's result (status,
    ``path_blocked``, its own command); the filter's (None when ``use_cbf`` is off); the
    circles used (tracked, at ``now``); the social speed scale applied."""

    v: float
    w: float
    dwa: DwaResult
    cbf: CbfResult | None
    circles: Circles
    speed_scale: float

    @property
    def status(self) -> DwaStatus:
        return self.dwa.status

    @property
    def path_blocked(self) -> bool:
        return self.dwa.path_blocked


class LocalPlanner:
    """The local navigation stack over a static map (see the module docstring)."""

    def __init__(self, static: OccupancyGrid, config: LocalPlannerConfig | None = None) -> None:
        self.config = checked(config or LocalPlannerConfig.for_base(LOCOBOT_KOBUKI))
        cfg = self.config
        self.costmap = RollingCostmap(static, cfg.costmap)
        self.tracker = ObstacleTracker(cfg.tracking)
        self.dwa = DwaPlanner(cfg.dwa)
        self.cbf = CbfFilter(cfg.cbf)
        self._tracks = Circles()
        self._t_tracks = 0.0
        self._u: tuple[float, float] | None = None

    def set_path(self, path: list[tuple[float, float]], now: float) -> None:
        """Follow a global path (map points [m]) from clock time ``now`` [s]."""
        self.dwa.set_path(path, now)

    def reset_command(self) -> None:
        """Forget the last command (the next tick starts from the measured velocity)."""
        self._u = None

    def observe(self, scan: LaserScan, pose: Pose2D) -> Circles:
        """Update the costmap and the tracks with ``scan``, taken with the base at
        ``pose`` in ``map``; returns the tracked circles at the scan's stamp."""
        pts = scan_to_map(scan, pose, self.config.costmap.clear_range)
        new = self.costmap.update(pts)
        detections = detect_obstacles(pts, new, self.config.obstacles)
        self._tracks = self.tracker.update(detections, scan.stamp)
        self._t_tracks = scan.stamp
        return self._tracks

    def circles_at(self, now: float) -> Circles:
        """The tracked circles moved to clock time ``now`` [s] at their velocities."""
        c = self._tracks
        return replace(c, centres=c.at_time(max(0.0, now - self._t_tracks)))

    def replan_grid(self, now: float, widen: float = 0.0) -> OccupancyGrid:
        """The map to re-plan on when the path is blocked: the static map, the costmap's
        marks and the non-person circles (as discs of their covering radius plus the
        filter's look-ahead, so that the inflated map keeps the planned path out of the
        zone the filter guards; plus ``widen`` [m], to leave out a gap the base could not
        pass)."""
        c = self.circles_at(now).select(~self._tracks.person)
        return self.costmap.merged_grid(c.centres, c.radii + self.config.cbf.lookahead + widen)

    def step(self, pose: Pose2D, v_meas: float, w_meas: float, now: float, dt: float,
             scan: LaserScan | None = None) -> LocalCommand:
        """One control tick: base ``pose`` in ``map``, measured ``(v_meas, w_meas)``, clock
        ``now`` [s], tick ``dt`` [s], and the newest scan if one arrived since the last tick."""
        cfg = self.config
        if scan is not None:
            self.observe(scan, pose)
        circles = self.circles_at(now)
        scale = speed_scale((pose.x, pose.y), circles.people, cfg.social)
        u0 = self._u if self._u is not None else (v_meas, w_meas)
        # the DWA keeps out of the zone the filter's look-ahead barrier guards (r_u + l)
        padded = replace(circles, safety_radii=circles.safety_radii + cfg.cbf.lookahead)
        d = self.dwa.step(pose, u0[0], u0[1], dt, now, self.costmap, padded, scale * cfg.limits.max_v)
        v, w, f = d.v, d.w, None
        if cfg.use_cbf:
            reference = None
            if d.trajectory.shape[0]:
                k = min(d.trajectory.shape[0], max(1, round(cfg.reference_time / cfg.dwa.step))) - 1
                x, y, th = d.trajectory[k]
                reference = Pose2D(float(x), float(y), float(th))
            f = self.cbf.filter(pose, (d.v, d.w), reference, circles, u0, dt, min(scale * cfg.limits.max_v, max(d.v, 0.0)))
            v, w = f.v, f.w
        self._u = (v, w)
        return LocalCommand(v, w, d, f, circles, scale)
