"""The local navigation tick: lidar -> rolling costmap and tracked circles -> DWA -> CLF-CBF.

:class:`LocalPlanner` composes the algorithm layer for a skill to call once per control
tick (it never blocks, never reads a clock and never talks to a device):

1. with a new scan: :func:`~mmexec.skills.navigation.obstacles.scan_to_map`, the rolling
   costmap's clearing and marking (which also says which hits are not the static map),
   clusters and circles of those hits, and the tracker (velocities, people);
2. the social speed scale from the nearest person caps the forward speed;
3. the DWA picks ``u_ref`` on the costmap and the circles, their safety radii grown by
   ``CbfConfig.lookahead`` ``l`` (headroom beyond the zone the filter guards; a DWA that
   planned into the zone would only be stopped by the filter), people moved at their
   tracked velocity;
4. the CLF-CBF filter makes ``u_ref`` safe against *every* circle, tracking the pose the
   DWA's rollout reaches ``reference_time`` seconds ahead. Within the nominal bounds it
   may only slow the base, never drive it faster than the DWA's command (the filter sees
   only the circles, and a faster command, fleeing someone who walks up from behind, is
   one the costmap never checked). When that leaves no safe command (someone stepped
   into the zone, or walks at the base), the filter may *escape*: back the base off at
   up to ``CbfConfig.escape_speed`` as far as the costmap shows room behind it for the
   footprint (:meth:`LocalPlanner.escape_room`; the lidar sees all round); when that
   cannot keep every barrier either, it brakes.

The caller acts on the DWA status and ``path_blocked`` (re-plan globally on
:meth:`LocalPlanner.replan_grid`; recover when ``STUCK``).
:func:`mmexec.skills.navigation.synthetic.run_closed_loop` shows the whole loop.
Frames: ``map``; m, rad, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

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
    drop_within,
    scan_to_map,
)
from mmexec.skills.navigation.social import PeopleWait, SocialConfig, speed_scale
from mmexec.skills.navigation.tracks import ObstacleTracker, TrackingConfig

__all__ = ["LocalCommand", "LocalPlanner", "LocalPlannerConfig", "barrier_fields"]

#: [m] how far along the heading, each way, :meth:`LocalPlanner.escape_room` looks
ESCAPE_LOOK = 0.3
#: [m/s] a base commanded at most this fast is waiting (:meth:`LocalPlanner.giving_way`)
WAIT_SPEED = 0.05
#: [m] a re-plan leaves out the costmap's marks this far round a person's covering circle
#: too (:meth:`LocalPlanner.replan_grid`): the lidar's hits on them and the trail behind
#: someone who walked up to the base, which their own body hides from the lidar
PERSON_TRAIL = 0.25
#: the lidar's hits within this fraction of the footprint radius of the base's centre are
#: the robot itself, and the costmap's marks there are cleared (:meth:`LocalPlanner.observe`):
#: the inscribed circle of a box base is at least 0.6 of the circumscribed one up to a 4:3
#: aspect (the UR platform's 0.62 x 0.52 m box: 0.26 of 0.405 m; a round base: all of it)
SELF_FRACTION = 0.6


def barrier_fields(f: CbfResult | None, circles: Circles, pose: Pose2D, v_meas: float) -> dict[str, Any]:
    """The event-log summary of the filter's result ``f`` over ``circles`` at ``pose``
    (see :meth:`LocalCommand.barrier_fields`)."""
    out: dict[str, Any] = {"h": None, "v_meas": round(float(v_meas), 3)}
    if f is None or not f.h.size:
        return out
    k = int(np.argmin(f.h))
    d = np.array([pose.x - circles.centres[k, 0], pose.y - circles.centres[k, 1]])
    n = float(np.hypot(*d))
    closing = float(d @ circles.velocities[k]) / n if n > 1e-9 else 0.0
    out.update(h=round(float(f.h[k]), 4), h_person=bool(circles.person[k]), h_closing=round(closing, 3),
               h_dist=round(n, 3), escaped=f.escaped)
    return out


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
    circles used (tracked, at ``now``); the social speed scale applied; the ``pose`` the
    tick was computed at."""

    v: float
    w: float
    dwa: DwaResult
    cbf: CbfResult | None
    circles: Circles
    speed_scale: float
    pose: Pose2D

    def barrier_fields(self, v_meas: float) -> dict[str, Any]:
        """The enforced barrier's summary for the event log (``nav_tick``): ``h`` [m^2]
        the smallest barrier value the filter enforced this tick (None without the filter
        or without circles), ``h_person`` whether that circle is a tracked person,
        ``h_closing`` [m/s] how fast it closes on the base (its tracked velocity towards
        the base's centre; > 0 approaching), ``h_dist`` [m] its centre's distance from
        the base's, ``v_meas`` [m/s] the base's measured speed,
        ``escaped`` whether the command came from the filter's escape solve; see
        :func:`mmexec.executive.campaign.navtruth.log_measures`."""
        return barrier_fields(self.cbf, self.circles, self.pose, v_meas)

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
        self.people_wait = PeopleWait(cfg.social)

    def set_path(self, path: list[tuple[float, float]], now: float) -> None:
        """Follow a global path (map points [m]) from clock time ``now`` [s]."""
        self.dwa.set_path(path, now)

    def reset_command(self) -> None:
        """Forget the last command (the next tick starts from the measured velocity), and
        start a new stretch of patience with people (the drive calls this when it starts
        and after each recovery)."""
        self._u = None
        self.people_wait.reset()

    def observe(self, scan: LaserScan, pose: Pose2D) -> Circles:
        """Update the costmap and the tracks with ``scan``, taken with the base at
        ``pose`` in ``map``; returns the tracked circles at the scan's stamp. Hits within
        :data:`SELF_FRACTION` of the footprint radius of the base's centre are the robot
        itself and are dropped, and the marks there cleared: the UR platforms' lidar, at
        the front of the base, now and then returned off the arm's base behind it, 0.05-0.1 m
        ahead of the centre; the marks stayed (the lidar's clearing starts past its
        minimum range), a trail of them was left along the way, and one under the base made
        the path ahead look blocked for good (corridors, seed 448725815: stuck 0.4 m short of
        the marker's viewpoint and at each stand-off)."""
        own = SELF_FRACTION * self.config.limits.radius
        pts = drop_within(scan_to_map(scan, pose, self.config.costmap.clear_range), (pose.x, pose.y), own)
        new = self.costmap.update(pts)
        self.costmap.clear_disc((pose.x, pose.y), own)
        detections = detect_obstacles(pts, new, self.config.obstacles)
        self._tracks = self.tracker.update(detections, scan.stamp)
        self._t_tracks = scan.stamp
        return self._tracks

    def room_behind(self, pose: Pose2D, distance: float, now: float, *, person_gap: float = 0.0,
                    from_here: bool = False) -> float:
        """How far [m] (up to ``distance``) the base can back straight off from ``pose``
        at clock time ``now`` [s]: the footprint keeps the costmap's clearance (``from_here``:
        or gets no closer than it is now) and every tracked circle's safety radius, plus
        ``person_gap`` [m] for people, unless it is inside that already and not getting
        closer. Sampled every half cell; stops at the first sample that fails."""
        radius = self.config.limits.radius
        circles = self.circles_at(now)
        step = 0.5 * self.costmap.resolution
        ds = np.arange(step, distance + 1e-9, step)
        pts = np.stack([pose.x - ds * math.cos(pose.theta), pose.y - ds * math.sin(pose.theta)], axis=1)
        floor = radius
        if from_here:
            floor = min(radius, float(self.costmap.clearance_at(np.array([[pose.x, pose.y]]))[0]))
        ok = self.costmap.clearance_at(pts) >= floor
        if len(circles):
            need = circles.safety_radii + np.where(circles.person, person_gap, 0.0)
            gap = np.hypot(pts[:, None, 0] - circles.centres[:, 0], pts[:, None, 1] - circles.centres[:, 1]) - need
            here = np.hypot(pose.x - circles.centres[:, 0], pose.y - circles.centres[:, 1]) - need
            ok &= ~np.any((gap < 0.0) & (gap < here), axis=1)
        blocked = np.flatnonzero(~ok)
        if not blocked.size:
            return max(distance, 0.0)
        return float(ds[blocked[0] - 1]) if blocked[0] > 0 else 0.0

    def circles_at(self, now: float) -> Circles:
        """The tracked circles moved to clock time ``now`` [s] at their velocities."""
        c = self._tracks
        return replace(c, centres=c.at_time(max(0.0, now - self._t_tracks)))

    def replan_grid(self, now: float, widen: float = 0.0, *, everyone: bool = False) -> OccupancyGrid:
        """The map to re-plan on when the path is blocked: the static map, the costmap's
        marks and the non-person circles (as discs of their covering radius plus the
        filter's look-ahead, so that the inflated map keeps the planned path out of the
        zone the filter guards; plus ``widen`` [m], to leave out a gap the base could not
        pass). People are left out (they move on), except, once the wait for them is
        spent (:meth:`giving_way`), those standing still: the re-plan goes round them.
        The costmap's marks on the people left out, and on the trail they leave within
        :data:`PERSON_TRAIL` of their circle (cells the lidar has not seen free since,
        behind someone who walked up to the base), are left out with them: with them
        in, two people standing by the base closed every way and the drive failed "no
        path" while only people were in the way. ``everyone``: every circle, people too,
        written in where it stands (whether any way is left while they all stay put)."""
        c = self.circles_at(now)
        keep = np.ones(len(c.radii), dtype=bool) if everyone else ~c.person
        if self.people_wait.spent:
            keep |= np.hypot(c.velocities[:, 0], c.velocities[:, 1]) <= self.config.tracking.moving_speed
        gone = c.select(~keep)
        c = c.select(keep)
        return self.costmap.merged_grid(c.centres, c.radii + self.config.cbf.lookahead + widen,
                                        ignore=(gone.centres, gone.radii + PERSON_TRAIL))

    def giving_way(self, circles: Circles, pose: Pose2D, now: float) -> bool:
        """Whether the base, not making progress at ``pose`` at clock time ``now`` [s], is
        waiting for people (``circles``' people within the social layer's ``slow_gap``,
        moving or standing) with patience left (:class:`~mmexec.skills.navigation.social.PeopleWait`):
        the drive does not count that as being stuck."""
        standing = self._u is None or abs(self._u[0]) <= WAIT_SPEED
        return self.people_wait.update(circles.people, (pose.x, pose.y), now, standing)

    def escape_room(self, pose: Pose2D) -> tuple[float, float]:
        """The speeds [m/s] ``(back, ahead)`` from which the base, moving straight along
        its heading, can still stop at full deceleration in the room the costmap shows
        behind and ahead of ``pose`` (up to :data:`ESCAPE_LOOK`): the footprint keeps
        the radius + margin from every static or marked cell, or, where it is already
        closer, gets no closer than now. At most ``CbfConfig.escape_speed`` (the filter's
        escape, :meth:`CbfFilter.filter`)."""
        cfg = self.config
        e = cfg.cbf.escape_speed
        if e <= 0.0:
            return 0.0, 0.0
        step = 0.5 * self.costmap.resolution
        ds = np.arange(step, ESCAPE_LOOK + 1e-9, step)
        c, s = math.cos(pose.theta), math.sin(pose.theta)
        sign = np.array([-1.0, 1.0])[:, None]
        pts = np.stack([pose.x + sign * ds * c, pose.y + sign * ds * s], axis=-1)
        clear = self.costmap.clearance_at(pts)
        here = float(self.costmap.clearance_at(np.array([[pose.x, pose.y]]))[0])
        need = min(cfg.limits.radius + cfg.margin, here)
        out = []
        for row in clear >= need:
            blocked = np.flatnonzero(~row)
            room = float(ds[blocked[0] - 1]) if blocked.size and blocked[0] > 0 else (0.0 if blocked.size else float(ds[-1]))
            out.append(min(e, math.sqrt(2.0 * cfg.limits.accel_v * max(0.0, room - step))))
        return out[0], out[1]

    def safe(self, pose: Pose2D, u_ref: tuple[float, float], reference: Pose2D | None, circles: Circles,
             u_prev: tuple[float, float], dt: float, v_cap: float, *, escape: bool = True) -> CbfResult:
        """The filter's command for ``u_ref`` (capped forward at ``v_cap`` [m/s]); with
        ``escape``, the escape may back the base off as far as the room measured behind
        ``pose`` allows (never forward: driven on past its goal, at the lab's depot stop
        while someone walked up behind, the base put the item 6 cm off and the place
        failed). Docking passes ``escape=False``: a stand-off must not be left (someone
        stepping in while the base docks makes it stand)."""
        room = (self.escape_room(pose)[0], 0.0) if escape else (0.0, 0.0)
        return self.cbf.filter(pose, u_ref, reference, circles, u_prev, dt, v_cap, room)

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
            f = self.safe(pose, (d.v, d.w), reference, circles, u0, dt, min(scale * cfg.limits.max_v, max(d.v, 0.0)))
            v, w = f.v, f.w
        self._u = (v, w)
        return LocalCommand(v, w, d, f, circles, scale, pose)
