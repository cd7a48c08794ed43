"""Path following with the local planner: how ``navigate``, ``approach`` and ``search``
drive the base when the robot profile sets ``nav.local_planner: true``.

The global A* path (on the static map inflated by the footprint radius and ``nav.margin``)
is followed by :class:`~mmexec.skills.navigation.local_planner.LocalPlanner`: the DWA on
the rolling lidar costmap, then the CLF-CBF filter against the tracked obstacle circles
(docs/algorithms.md, "Local navigation"). Per control tick, never blocking:

1. the base's state: a bumper or cliff fault starts the *contact recovery* (below); any
   other fault brakes and fails (EXECUTION), as the plain drive does;
2. the newest lidar scan, when its stamp is new, updates the costmap and the tracks;
3. one :meth:`LocalPlanner.step` gives the command;
4. the DWA's reports are acted on:

   * **path blocked** (by anything but a person: people move on) -> a global re-plan:
     A* on the static map with the costmap's marks and the non-person circles written in
     (:meth:`LocalPlanner.replan_grid`), inflated as the static map is, at most every
     ``nav.replan_interval`` seconds; a re-plan that finds no way keeps the old path (the
     DWA stops in front of the obstacle and the stuck recovery takes over);
   * **stuck** (no progress along the path for the DWA's ``stuck_time``) -> *recovery*:
     brake, turn in place once round (the lidar clears the marks of what has moved away
     and sees what is around; only with :data:`RECOVERY_TURN_ROOM` to spare round the
     footprint, since an arm held out sweeps past it), back off
     ``nav.recovery_back_off`` where the costmap and the circles leave room behind, re-plan; after ``nav.recoveries`` of them the drive
     fails: EXECUTION "stuck on the way to ..." or, when no way was found at the last
     re-plan, PLANNING "no path to ...: blocked by obstacles the map does not show";
   * **goal reached** -> brake, turn to the goal heading, done.

**Docking.** Within ``dock_distance`` of the goal, along a straight way the costmap shows
clear, the drive hands over to the plain drive's pure-pursuit tracker (then its heading
alignment), its command still passed through the CLF-CBF filter against the tracked
circles (which may slow it or steer it, never speed it up): a stand-off in front of a shelf or the depot lies closer to the furniture than
the DWA's clearance term likes (it stops short, in a local minimum of its score), and a
pick needs the stand-off to the tolerance the tracker reaches. Docking ends back in the
DWA (with a re-plan) when something appears on that straight way.

**Contact recovery** (``bumper_*``, ``cliff_*``): stop; pin the contact in the local
costmap (an arc just outside the footprint at the sensor's bearing, unless it reaches an
obstacle of the static map, which explains it: the lidar cannot clear it, since what the
bumper felt may be below the scan plane); back off; re-plan. More than
``nav.recoveries`` contacts in one drive fail it (EXECUTION, naming the faults), and so
does a bumper that stays pressed while the base tries to back off (the Kobuki driver
refuses motion while one is).

**A held item** (:mod:`mmexec.skills.navigation.carried`): when the gripper holds
something the arm carries out past the footprint, every command (the DWA's and docking's)
is checked over the time the base needs to stop from it for sweeping the item into what
reaches its height (the map less the robot's scene boxes lower than the item, and the
lidar's marks); one that would stops the base, which turns to its path the way round
that keeps the item clear. Turns in place (facing the path, the goal's heading, the
recovery's turn) go the way that keeps it clear, backing off first when neither does.
A planned path comes into the goal along its heading (or within 80 degrees of it) for
the item's reach, so the item does not swing through what stands beside the stop (the
lab's crate by the depot). Docking stopped by the item near the goal aligns there.

**Pose jumps**: a localised pose that jumps between two ticks by more than the base's
motion explains (``pose_jump``: a re-localisation after a kidnap) brakes the base,
forgets the costmap's marks (placed from the old belief) and plans again from the new
pose, at most ``jump_replans`` times a drive, as the plain drive does; a base that stops
being localised fails the drive (EXECUTION "lost localisation ...").

For the live console the drive publishes the path it follows under ``nav.path`` (a new
list of ``[x, y]`` [m] each time it is planned; empty when the drive ends) and the tracked
people under ``nav.people`` (``{"id", "x", "y", "vx", "vy"}`` in ``map`` [m, m/s]). Event
log records: ``nav_plan`` (why, the path's points and length), ``nav_tick`` (each tick:
estimated pose, the command sent and the DWA's, the smallest barrier value ``h`` [m^2]
over the circles, how many barriers bound, the DWA status, the social speed scale, the
tracked people), ``nav_recovery``, ``nav_contact``, ``nav_item`` (what the held item
made the drive do) and ``nav_replan`` (a pose jump).

Frames: ``map``; m, rad, s. Nothing here reads the simulator's ground truth.
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Callable, Generator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import (
    BLIND_FAULTS,
    Base,
    BaseState,
    LaserScan,
    Lidar,
    OccupancyGrid,
    Pose2D,
)
from mmexec.skills.base import FailureKind, SkillCancelled, SkillContext, SkillFailure
from mmexec.skills.navigation.astar import line_is_free, plan_path, simplify_path
from mmexec.skills.navigation.carried import ItemGuard, held_item, layer_floor, tall_layer
from mmexec.skills.navigation.cbf import QpStatus
from mmexec.skills.navigation.dwa import DwaStatus
from mmexec.skills.navigation.grid import CostMap, inflate
from mmexec.skills.navigation.local_planner import (
    WAIT_SPEED,
    LocalCommand,
    LocalPlanner,
    LocalPlannerConfig,
    barrier_fields,
)
from mmexec.skills.navigation.obstacles import Circles
from mmexec.skills.navigation.tracker import PathTracker, TrackerConfig
from mmexec.skills.primitives import brake

__all__ = [
    "CONTACT_BEARINGS",
    "WORLD_LOCAL_PLANNER",
    "WORLD_PATH",
    "WORLD_PEOPLE",
    "LocalDrive",
    "LocalDriveConfig",
    "contact_points",
    "local_planner",
]

log = logging.getLogger(__name__)

#: ``ctx.world`` keys: the path being followed (the live console draws it), the tracked
#: people, and the run's local planner (its costmap and tracks outlive one drive)
WORLD_PATH = "nav.path"
WORLD_PEOPLE = "nav.people"
WORLD_LOCAL_PLANNER = "nav.local_planner"

#: bearing [rad] in ``base_link`` of what a contact sensor felt, by the fault's side
CONTACT_BEARINGS = {"left": math.pi / 4, "centre": 0.0, "right": -math.pi / 4}
#: [s] how long a pressed bumper may keep the base from backing off before the drive fails
CONTACT_CLEAR_TIME = 2.0
#: [m/s] backing-off speed (recoveries and contacts)
BACK_OFF_SPEED = 0.1
#: [m] room beyond the footprint a recovery needs round the base to turn once round: an
#: arm held out (carrying) reaches past the footprint, and swept into furniture it hit it
RECOVERY_TURN_ROOM = 0.25
#: [m] the path's direction at the start of a drive is taken to its first point this far
#: from the base (:meth:`LocalDrive._face_path`)
FACE_PATH_DISTANCE = 0.3
#: [m] after a stuck recovery, re-plans first try with the non-person circles this much
#: wider (:meth:`LocalPlanner.replan_grid`), so a gap the base stood in is left out when
#: there is another way
STUCK_WIDEN = 0.15
#: ``ctx.world`` key: the static layer of the obstacles that reach a held item's height,
#: with the map and the height it was built for (:func:`LocalDrive._item_guard`)
WORLD_TALL_LAYER = "nav.tall_layer"
#: [s] each command is checked for sweeping a held item into something over the time the
#: base needs to stop from it plus this (two ticks and a half at 20 Hz)
ITEM_HORIZON = 0.125
#: [m] a dock whose next move would sweep the held item into something ends this close to
#: the goal with the heading aligned (the item-safe way) instead of moving further
ITEM_DOCK_NEAR = 0.08
#: [s] the DWA drives this long before docking is tried again after the item stopped it
ITEM_DOCK_PAUSE = 2.0
#: [m] how far back a turn the item cannot make either way backs off before trying again
ITEM_BACK_OFF = 0.15
#: [s] how long a turn in place that something walked into the held item's sweep of
#: holds (base stopped, the sweep ahead checked each tick) before it looks for another
#: way round (:meth:`LocalDrive._turn`)
ITEM_TURN_HOLD = 3.0
#: docking's progress: the distance to the goal [m], then the heading error [rad], must
#: fall by this much below its best within the DWA's ``stuck_time`` (a base that crept a
#: centimetre closer every few seconds, held back by someone standing by the stop,
#: restarted the count for 90 s)
DOCK_PROGRESS = (0.03, 0.05)
#: [m] with an item held, the path's last stretch runs straight into the goal for the
#: item's reach past the footprint plus this (or a quarter of it where that has no room;
#: :meth:`LocalDrive._approach_point`) ...
ITEM_APPROACH = 0.2
#: [rad] ... along the goal's heading turned by the first of these that keeps the item clear
ITEM_APPROACH_TURNS = (0.0, 0.35, -0.35, 0.7, -0.7, 1.05, -1.05, 1.4, -1.4)
#: [s] a pose jump is looked for between two poses at most this far apart (consecutive
#: ticks of the DWA or docking; not across a turn or a back-off, whose motion is not logged)
JUMP_WINDOW = 0.2
#: [m] the planned path's shortcuts keep as far from obstacles as A*'s path did, up to this
#: beyond the inflation (A*'s own penalty distance): a path pulled onto a corner by its
#: shortcuts left the DWA a passage its clearance term preferred standing still to
PATH_KEEP = 0.3
#: [m] how far outside the filter's zone a moved goal lies beyond the look-ahead
#: (:meth:`LocalDrive._leave_zones`): the barrier sits at the look-ahead point, so at a goal
#: only ``l`` outside the zone the base could not turn towards the obstacle
ZONE_SLACK = 0.05


@dataclass(frozen=True)
class LocalDriveConfig:
    """What one drive needs from the profile: the ``planner``'s configuration (its base
    limits, margin, DWA goal tolerance); ``margin`` [m] the global plan inflates by on top
    of the footprint radius; ``replan_interval`` [s] between two re-plans of a blocked
    path; ``recoveries`` (stuck recoveries, and contacts, before failing);
    ``back_off`` [m] how far a recovery backs off; ``heading_tolerance`` [rad] at the
    goal; ``goal_search`` [m] how far a goal an obstacle covers may move (0: fail);
    ``zone_goal_search`` [m] how far a goal inside the zone the filter guards round an
    obstacle the map does not show may move (0, the default: never; a search viewpoint a
    box stands on may move, a pick's stand-off or the depot stop may not); ``tracker`` the docking tracker's limits and tolerances, ``dock_distance`` [m] how
    close to the goal docking starts; ``pose_jump`` ([m], [rad]): a pose change between
    two ticks this much larger than the base's motion explains is the localiser
    correcting the pose, and the path is planned again from the new pose, at most
    ``jump_replans`` times in one drive; ``view_slack`` [m]: the goal is a place to look
    from, and a drive stuck this near it (people, or an obstacle, between the base and
    it) ends where it stands, turned to the goal's heading (0, the default: never)."""

    planner: LocalPlannerConfig
    margin: float
    tracker: TrackerConfig
    replan_interval: float = 1.0
    recoveries: int = 3
    back_off: float = 0.2
    heading_tolerance: float = 0.04
    goal_search: float = 0.3
    zone_goal_search: float = 0.0
    dock_distance: float = 0.5
    pose_jump: tuple[float, float] = (0.15, 0.15)
    jump_replans: int = 3
    view_slack: float = 0.0


def local_planner(ctx: SkillContext, config: LocalPlannerConfig) -> LocalPlanner:
    """The run's local planner for ``config`` over the robot's map, kept in the world
    model (``nav.local_planner``) so the costmap's marks and the tracks carry over from
    one drive to the next; a new one when the map or the configuration changes."""
    occ = ctx.robot.occupancy
    assert occ is not None
    cached = ctx.world.get(WORLD_LOCAL_PLANNER)
    if cached is not None and cached[0] is occ and cached[1].config == config:
        planner: LocalPlanner = cached[1]
        return planner
    planner = LocalPlanner(occ, config)
    ctx.world[WORLD_LOCAL_PLANNER] = (occ, planner)
    return planner


def contact_points(pose: Pose2D, faults: frozenset[str], radius: float, *, spread: float = 0.5,
                   n: int = 7, beyond: float = 0.03) -> np.ndarray:
    """Map points (k, 2) [m] where the contact sensors named in ``faults`` (``bumper_left``,
    ``cliff_centre``, ...) felt something: for each, an arc of ``n`` points over
    ``+-spread`` [rad] around its bearing (:data:`CONTACT_BEARINGS`), ``beyond`` [m]
    outside the footprint ``radius`` of the base at ``pose``."""
    pts = []
    for f in sorted(faults):
        side = f.rsplit("_", 1)[-1]
        bearing = CONTACT_BEARINGS.get(side, 0.0)
        for a in np.linspace(bearing - spread, bearing + spread, n):
            th = pose.theta + float(a)
            pts.append((pose.x + (radius + beyond) * math.cos(th), pose.y + (radius + beyond) * math.sin(th)))
    return np.array(pts, dtype=float).reshape(-1, 2)


def cell_to_world_array(grid: OccupancyGrid, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map coordinates ``(x, y)`` [m] of the centres of cells ``(rows, cols)`` (arrays):
    the vectorised :func:`~mmexec.skills.navigation.grid.cell_to_world`."""
    o = grid.origin
    gx, gy = (cols + 0.5) * grid.resolution, (rows + 0.5) * grid.resolution
    c, s = math.cos(o.theta), math.sin(o.theta)
    return o.x + c * gx - s * gy, o.y + s * gx + c * gy


def is_contact(fault: str) -> bool:
    """A bumper or cliff sensor (the faults the contact recovery handles)."""
    return fault.startswith(("bumper_", "cliff_"))


def _rounded(values: Any, digits: int = 3) -> Any:
    """Floats (or nested lists of them) rounded for the event log."""
    if isinstance(values, (list, tuple)):
        return [_rounded(v, digits) for v in values]
    return round(float(values), digits)


class LocalDrive:
    """One drive to ``goal`` (see the module docstring): construct, then ``yield from
    drive.run()``, which returns the pose reached. ``path`` (map points) is followed if
    given, otherwise planned; ``static`` is the static map inflated for the base;
    ``status(ctx, state, **fields)`` writes the seed's base states (``to_goal``,
    ``goal_ok``, ``goal_fail``, ``idle``)."""

    #: [m] a re-planned path longer than the best path length left by more than this is a
    #: way round, and progress is counted afresh along it
    DETOUR = 0.3

    def __init__(self, ctx: SkillContext, base: Base, lidar: Lidar, goal: Pose2D, label: str, *,
                 config: LocalDriveConfig, static: CostMap, timeout: float,
                 path: list[tuple[float, float]] | None, status: Callable[..., None]) -> None:
        self.ctx, self.base, self.lidar = ctx, base, lidar
        self.goal, self.label, self.config = goal, label, config
        self._asked = goal  # the goal asked for (self.goal may move out of an obstacle's zone)
        self.static, self.timeout, self.status = static, timeout, status
        self.planner = local_planner(ctx, config.planner)
        self._given_path = path
        self._last_stamp = -math.inf
        self._last_replan = -math.inf
        self._last_tick = ctx.clock.now()
        self.recoveries = 0
        self.contacts = 0
        self.replans = 0
        self._no_way = False  # the last re-plan found no way to the goal
        self._widen = 0.0  # [m] re-plans widen the circles by this (after a stuck recovery)
        self._path: list[tuple[float, float]] | None = None
        self._best, self._t_best = math.inf, ctx.clock.now()  # progress: least path length left, and when
        self._deadline = ctx.clock.now() + timeout
        self._people_shown = False
        self._guard: ItemGuard | None = None  # set by run() when the gripper holds something
        self._no_dock_until = -math.inf  # [s] docking paused (the held item stopped it)
        self._prev: tuple[Pose2D, float, float, float] | None = None  # pose, v, w and clock of the last tick
        self._jump = 0.0  # [m] the pose's change at the last tick
        self._item_blocked = False  # the last turn was not made: it would sweep the held item
        self.jump_replans = 0

    # ------------------------------------------------------------------ planning
    def _inflated(self, now: float, widen: float = 0.0, *, everyone: bool = False) -> CostMap:
        """The map to plan on now: the static one, or with what the lidar and the
        contact sensors found written in (when they found anything), except under the
        base's own footprint: the base stands there, so what was marked there (the trail
        of someone who walked past, a circle drawn round a person not yet told from
        furniture) is not there, and A* must be able to start. ``everyone``: people
        written in too (LocalPlanner.replan_grid)."""
        cm = self.planner.costmap
        tracks = self.planner.circles_at(now)
        if not cm.marks.any() and not np.any(~tracks.person) and not (everyone and len(tracks.radii)):
            return self.static
        lim = self.config.planner.limits
        grid = self.planner.replan_grid(now, widen, everyone=everyone)
        pose = self.base.state().pose
        data = np.array(grid.data, copy=True)
        rows, cols = np.indices(data.shape)
        xy = np.stack(cell_to_world_array(grid, rows, cols), axis=-1)
        under = np.hypot(xy[..., 0] - pose.x, xy[..., 1] - pose.y) <= lim.radius
        static = np.asarray(self.static.grid.data)
        data[under & (static < 50) & (static >= 0)] = 0
        cm = inflate(replace(grid, data=data), lim.radius, self.config.margin)
        # and A* must be able to leave: the inflation round what is near the base is
        # passable from the base outwards (only obstacle cells themselves are not)
        near = np.hypot(xy[..., 0] - pose.x, xy[..., 1] - pose.y) <= lim.radius + self.config.margin + grid.resolution
        return replace(cm, blocked=cm.blocked & ~(near & (cm.clearance > 0.0)))

    def _plan(self, now: float, why: str, *, on_static: bool = False) -> list[tuple[float, float]] | None:
        """A* from the base's pose to the goal on :meth:`_inflated` (``on_static``: on the
        static map alone), simplified, from the base to the goal exactly. None (logged)
        when there is no way."""
        start = self.base.state().pose
        cm = self.static if on_static else self._inflated(now)
        if not on_static:
            self._leave_zones(cm, now)
            if self._widen > 0.0:
                # stuck before: keep out of gaps between obstacles the map does not show
                # that are only just wide enough (the DWA and the filter stood in one), if
                # there is another way
                path = self._plan_on(self._inflated(now, self._widen), start, why, log_none=False)
                if path is not None:
                    return path
        return self._plan_on(cm, start, why)

    def _plan_on(self, cm: CostMap, start: Pose2D, why: str, *, log_none: bool = True) -> list[tuple[float, float]] | None:
        """A* on ``cm`` from ``start`` to the goal (moved to a free point within
        ``goal_search`` when ``cm`` covers it), simplified; None (logged unless not
        ``log_none``) when there is no way."""
        gx, gy = self.goal.x, self.goal.y
        if not cm.is_free(gx, gy) and self.config.goal_search > 0:
            free = cm.nearest_free(gx, gy, self.config.goal_search)
            if free is not None:
                gx, gy = free
        grid_path = None
        pre = self._approach_point(cm, start, gx, gy)
        if pre is not None:
            grid_path = plan_path(cm, (start.x, start.y), pre)
            if grid_path is not None:
                grid_path = [*simplify_path(cm, grid_path, keep_clearance=PATH_KEEP), (gx, gy)]
        if grid_path is None and cm.is_free(gx, gy):
            grid_path = simplify_path(cm, plan_path(cm, (start.x, start.y), (gx, gy)) or [],
                                      keep_clearance=PATH_KEEP) or None
        if grid_path is None:
            if log_none:
                self.ctx.emit("nav_plan", why=why, found=False, label=self.label, node=self.ctx.node_path)
            return None
        return [(start.x, start.y), *grid_path[1:-1], (gx, gy)] if len(grid_path) > 1 else [(gx, gy)]

    def _approach_point(self, cm: CostMap, start: Pose2D, gx: float, gy: float) -> tuple[float, float] | None:
        """With an item held out ahead: the point the path comes through so that its last
        stretch runs straight into goal ``(gx, gy)`` along the goal's heading, or within
        :data:`ITEM_APPROACH_TURNS` of it (the first of those that works), for the item's
        reach past the footprint plus :data:`ITEM_APPROACH`, with the item clear of what
        reaches its height all along the stretch and in the turn to the goal's heading
        at its end, as a fork truck comes into a rack: arriving from the side, the turn
        at the goal swings the item through whatever stands beside the stop (the lab's
        crate by the depot). None without an item, when no such stretch is free on
        ``cm``, or when the base is already that near the goal and the straight way in
        from where it is keeps the item clear (otherwise it goes back out to the point:
        a base that came in from the side stood by the stop for good)."""
        guard = self._guard
        if guard is None:
            return None
        reach = guard.item.reach - self.config.planner.limits.radius
        if math.hypot(gx - start.x, gy - start.y) <= reach + ITEM_APPROACH and \
                self._stretch_clear(guard, start.x, start.y, gx, gy, math.atan2(gy - start.y, gx - start.x)):
            return None
        for d, delta in itertools.product((reach + ITEM_APPROACH, reach + ITEM_APPROACH / 4), ITEM_APPROACH_TURNS):
            th = self.goal.theta + delta
            px, py = gx - d * math.cos(th), gy - d * math.sin(th)
            if not cm.is_free(px, py) or not line_is_free(cm, (px, py), (gx, gy)):
                continue
            if self._stretch_clear(guard, px, py, gx, gy, th):
                return px, py
        return None

    def _stretch_clear(self, guard: ItemGuard, px: float, py: float, gx: float, gy: float, th: float) -> bool:
        """Whether driving straight from ``(px, py)`` to ``(gx, gy)`` heading ``th`` [rad],
        then turning to the goal's heading there, keeps the held item clear."""
        d = math.hypot(gx - px, gy - py)
        f = np.linspace(0.0, 1.0, max(2, math.ceil(d / 0.05) + 1))
        stretch = np.stack([px + f * (gx - px), py + f * (gy - py), np.full(f.size, th)], axis=1)
        return float(guard.gaps(stretch).min()) >= guard.margin and \
            guard.turn_clear(Pose2D(gx, gy, th), wrap_angle(self.goal.theta - th))

    def _follow_path(self, path: list[tuple[float, float]], why: str, now: float) -> None:
        """Follow ``path`` from now: published (``nav.path``) and logged (``nav_plan``)
        unless it is the path already followed (a re-plan that found the same way)."""
        same = (self._path is not None and len(path) == len(self._path)
                and all(math.hypot(a[0] - b[0], a[1] - b[1]) < 0.05 for a, b in zip(path[1:], self._path[1:])))
        self.planner.set_path(path, now)
        self._path = path
        length = sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(path))
        if not math.isfinite(self._best) or length > self._best + self.DETOUR:  # (a longer way round) counts from here
            self._best, self._t_best = length, now
        if same:
            return
        self.ctx.world[WORLD_PATH] = [[float(x), float(y)] for x, y in path]
        self.ctx.emit("nav_plan", why=why, found=True, label=self.label, points=_rounded(path),
                      length=round(length, 3), node=self.ctx.node_path)

    def _replan(self, now: float, why: str) -> bool:
        """Plan again and follow the new path; False (the old path kept) when there is no way."""
        self._last_replan = now
        path = self._plan(now, why)
        self._no_way = path is None
        if path is None:
            return False
        self.replans += 1
        self._follow_path(path, why, now)
        return True

    def _stuck(self, remaining: float, now: float) -> bool:
        """No progress: the path length left (``remaining`` [m]) has not fallen by the
        DWA's ``stuck_progress`` below its best for ``stuck_time`` seconds. Kept here, not
        in the DWA, because a re-plan restarts the DWA's own count (and one that finds the
        same way again every second would hide a standstill)."""
        dwa = self.config.planner.dwa
        if remaining < self._best - dwa.stuck_progress:
            self._best, self._t_best = remaining, now
        return now - self._t_best > dwa.stuck_time

    def _giving_way(self, circles: Circles, pose: Pose2D) -> bool:
        """Someone known as a person (walking, or standing after having walked) is within
        the social layer's ``slow_gap`` of the base and the patience with them is not
        spent: whatever the base does now (slowing, stopping while the filter holds it),
        it is giving way, not stuck (:meth:`LocalPlanner.giving_way`; once spent, the
        recoveries count and re-plans go round whoever stands there)."""
        return self.planner.giving_way(circles, pose, self.ctx.clock.now())

    def _goal_guarded(self) -> float | None:
        """The goal's distance [m] to the nearest non-person circle whose safety zone (its
        radius plus the filter's look-ahead) holds the goal, or None: a goal the filter
        keeps the base from ever reaching."""
        c = self.planner.circles_at(self.ctx.clock.now())
        c = c.select(~c.person)
        if not len(c):
            return None
        d = np.hypot(c.centres[:, 0] - self.goal.x, c.centres[:, 1] - self.goal.y)
        inside = d < c.safety_radii + self.config.planner.cbf.lookahead
        return float(d[inside].min()) if inside.any() else None

    def _leave_zones(self, cm: CostMap, now: float) -> bool:
        """A goal inside the zone the filter guards round a non-person circle (an
        obstacle the map does not show, standing on or beside the goal; the zone here is
        the circle's safety radius plus twice the look-ahead and :data:`ZONE_SLACK`, so
        the base can also turn at the goal) is one the base never reaches: move it to the
        nearest point within ``zone_goal_search`` of the goal asked for that lies outside
        every such zone and is free on ``cm`` (logged ``nav_goal_moved``). True when the
        goal moved. A goal left where it is fails after the recoveries, saying why."""
        limit = self.config.zone_goal_search
        c = self.planner.circles_at(now)
        c = c.select(~c.person)
        if limit <= 0 or not len(c):
            return False
        zone = c.safety_radii + 2.0 * self.config.planner.cbf.lookahead + ZONE_SLACK
        if np.all(np.hypot(c.centres[:, 0] - self.goal.x, c.centres[:, 1] - self.goal.y) >= zone):
            return False
        asked = self._asked
        rings = np.arange(1, round(limit / 0.05) + 1) * 0.05
        ang = np.linspace(-math.pi, math.pi, 32, endpoint=False)
        here = self.base.state().pose
        for r in rings:
            xs, ys = asked.x + r * np.cos(ang), asked.y + r * np.sin(ang)
            d = np.hypot(xs[:, None] - c.centres[:, 0], ys[:, None] - c.centres[:, 1])
            free = [k for k in np.flatnonzero(np.all(d >= zone, axis=1)) if cm.is_free(float(xs[k]), float(ys[k]))]
            if free:
                k = min(free, key=lambda k: math.hypot(xs[k] - here.x, ys[k] - here.y))
                old = self.goal
                self.goal = Pose2D(float(xs[k]), float(ys[k]), old.theta)
                self.ctx.emit("nav_goal_moved", label=self.label, goal=_rounded([asked.x, asked.y]),
                              to=_rounded([self.goal.x, self.goal.y]), by=round(float(r), 3),
                              node=self.ctx.node_path)
                log.info("%s: goal moved %.2f m (from %.2f, %.2f), out of the zone round an obstacle the map "
                         "does not show", self.label, r, old.x, old.y)
                return True
        return False

    def _restart_progress(self, now: float) -> None:
        self._best, self._t_best = math.inf, now

    # ------------------------------------------------------------------ ticking
    def _scan(self) -> LaserScan | None:
        """The lidar's newest scan when it is new (None otherwise or on a dropout)."""
        scan = self.lidar.scan()
        if scan is None or scan.stamp <= self._last_stamp:
            return None
        self._last_stamp = scan.stamp
        return scan

    def _observe(self) -> None:
        """Feed a new scan to the costmap and the tracks (while turning or backing off)."""
        scan = self._scan()
        if scan is not None:
            self.planner.observe(scan, self.base.state().pose)

    def _log_tick(self, cmd: LocalCommand, pose: Pose2D) -> None:
        people = cmd.circles.people
        rows = [{"id": int(i), "x": float(c[0]), "y": float(c[1]), "vx": float(v[0]), "vy": float(v[1])}
                for i, c, v in zip(people.ids, people.centres, people.velocities)]
        if rows or self._people_shown:
            self.ctx.world[WORLD_PEOPLE] = rows
            self._people_shown = bool(rows)
        f = cmd.cbf
        self.ctx.emit("nav_tick", pose=_rounded([pose.x, pose.y, pose.theta]), cmd=_rounded([cmd.v, cmd.w]),
                      ref=_rounded([cmd.dwa.v, cmd.dwa.w]),
                      **cmd.barrier_fields(self.base.state().v),
                      active=int(f.active.sum()) if f is not None else 0,
                      infeasible=f is not None and f.status is QpStatus.INFEASIBLE,
                      status=cmd.status.value, blocked=cmd.path_blocked, scale=round(cmd.speed_scale, 3),
                      circles=len(cmd.circles),
                      people=[_rounded([r["x"], r["y"], r["vx"], r["vy"]], 2) for r in rows])

    def _fail(self, kind: FailureKind, reason: str, why: str) -> SkillFailure:
        self.status(self.ctx, "goal_fail", reason=why)
        return SkillFailure(kind, reason)

    def _check_faults(self) -> frozenset[str]:
        """The base's contact faults now (empty: none); any other fault fails the drive."""
        faults = self.base.state().faults
        other = frozenset(f for f in faults if not is_contact(f))
        if other:
            raise self._fail(FailureKind.EXECUTION, f"base fault on the way to {self.label}: {', '.join(sorted(faults))}",
                             f"base fault: {', '.join(sorted(faults))}")
        return faults

    def run(self) -> Generator[None, None, Pose2D]:
        """The drive (see the class docstring); returns the pose reached."""
        ctx, base = self.ctx, self.base
        now = ctx.clock.now()
        self.planner.reset_command()
        # what is round the base now (the costmap was last fed in the previous drive: after
        # a pick someone stood behind the base, and the turn to the path, checked against the
        # old marks, swung the item into them)
        self._observe()
        self._guard = self._item_guard()
        if self._given_path is not None:
            start, given = base.state().pose, self._given_path
            # a grid path runs between cell centres: from the base, to the goal exactly
            path = [(start.x, start.y), *given[1:-1], (self.goal.x, self.goal.y)] if len(given) > 1 \
                else [(self.goal.x, self.goal.y)]
            why = "given"
        else:
            why = "start"
            planned = self._plan(now, why)
            if planned is None:
                # what the lidar marked closes every way now: start on the map's own way
                # (the marks may be someone standing by; a re-plan, or the recoveries, decide)
                why = "start on the map"
                planned = self._plan(now, why, on_static=True)
                self._no_way = planned is not None
            if planned is None:
                self.status(ctx, "goal_fail", goal=[self.goal.x, self.goal.y, self.goal.theta], reason="no path")
                self.status(ctx, "idle")
                raise SkillFailure(FailureKind.PLANNING, f"no path to {self.label} ({self.goal.x:.2f}, {self.goal.y:.2f})")
            path = planned
        self._follow_path(path, why, now)
        self.status(ctx, "to_goal", goal=_rounded([self.goal.x, self.goal.y, self.goal.theta]), label=self.label)
        try:
            yield from self._follow()
            reached = base.state().pose
            self.status(ctx, "goal_ok", pose=_rounded([reached.x, reached.y, reached.theta]))
            return reached
        except SkillCancelled:
            yield from brake(ctx, base)
            raise
        except SkillFailure:
            yield from brake(ctx, base)
            raise
        finally:
            ctx.world[WORLD_PATH] = []
            if self._people_shown:
                ctx.world[WORLD_PEOPLE] = []
            self.status(ctx, "idle")

    def _timed_out(self, now: float) -> bool:
        return now > self._deadline

    def _item_guard(self) -> ItemGuard | None:
        """The guard of the item the gripper holds now (None: nothing held beyond the
        footprint), over the static layer of what reaches its height (cached in the world
        model per map and height, the height rounded down to the centimetre)."""
        robot = self.ctx.robot
        item = held_item(robot, self.config.planner.limits.radius)
        if item is None or robot.occupancy is None:
            return None
        floor = layer_floor(item.floor)
        cached = self.ctx.world.get(WORLD_TALL_LAYER)
        if cached is not None and cached[0] is robot.occupancy and cached[1] == floor:
            layer = cached[2]
        else:
            cm = self.config.planner.costmap
            layer = tall_layer(robot.occupancy, robot.scene, floor, occupied_threshold=cm.occupied_threshold,
                               unknown_is_obstacle=cm.unknown_is_obstacle)
            self.ctx.world[WORLD_TALL_LAYER] = (robot.occupancy, floor, layer)
        log.info("%s: holding an item %.2f m out (%.2f m up and higher): the drive keeps it clear",
                 self.label, item.reach, item.floor)
        return ItemGuard(item, self.planner.costmap, layer)

    # ------------------------------------------------------------------ pose jumps
    def _jumped(self, st: BaseState, now: float) -> bool:
        """Whether the localised pose jumped since the last tick (``pose_jump``: more than
        the base's motion explains, e.g. a re-localisation after a kidnap), while
        re-plans for jumps are left; EXECUTION failure when the base is no longer
        localised."""
        if not st.localised:
            raise self._fail(FailureKind.EXECUTION, f"lost localisation on the way to {self.label}: the scans no "
                             "longer match the map at the estimated pose (stopped; run 'localize')", "not localised")
        prev, self._prev = self._prev, (st.pose, st.v, st.w, now)
        if prev is None or self.jump_replans >= self.config.jump_replans:
            return False
        pose, v, w, t = prev
        dt = max(now - t, 0.0)
        if dt > JUMP_WINDOW:  # the drive turned or backed off in between: nothing to compare
            return False
        self._jump = pose.distance_to(st.pose)
        moved = self._jump - max(abs(v), abs(st.v)) * dt
        turned = abs(wrap_angle(st.pose.theta - pose.theta)) - max(abs(w), abs(st.w)) * dt
        return moved > self.config.pose_jump[0] or turned > self.config.pose_jump[1]

    def _after_jump(self, st: BaseState, now: float) -> Generator[None, None, None]:
        """Brake and plan again from the new pose (``nav_replan``): the path was planned
        from where the base was believed to be, and the costmap's marks were placed from
        that belief too (forgotten: the next scans mark again)."""
        self.jump_replans += 1
        self.ctx.emit("nav_replan", label=self.label, reason="the localised pose jumped",
                      jump=round(self._jump, 3), node=self.ctx.node_path)
        log.info("%s: the localised pose jumped; planning again", self.label)
        yield from brake(self.ctx, self.base)
        self.planner.costmap.clear_marks()
        self._restart_progress(self.ctx.clock.now())
        self._replan(self.ctx.clock.now(), "pose jump")
        self.planner.reset_command()
        self._prev = None

    def _face_path(self, *, force: bool = False) -> Generator[None, None, None]:
        """As the plain drive's tracker does: when the path leaves more than the tracker's
        ``turn_in_place_angle`` off the base's heading (``force``: more than the heading
        tolerance), turn in place to it first. The DWA
        would turn while driving off, in an arc that swung the base half a metre off the
        path (after a pick, facing the shelf, with the path to the depot behind it), and
        the arm held out with it (into the lab's crate by the depot)."""
        pose = self.base.state().pose
        path = self._path or []
        ahead = next(((x, y) for x, y in path if math.hypot(x - pose.x, y - pose.y) > FACE_PATH_DISTANCE), None)
        if ahead is None and force and math.hypot(self.goal.x - pose.x, self.goal.y - pose.y) > FACE_PATH_DISTANCE / 3:
            ahead = (self.goal.x, self.goal.y)
        if ahead is None:
            return
        direction = math.atan2(ahead[1] - pose.y, ahead[0] - pose.x)
        limit = self.config.heading_tolerance if force else self.config.tracker.turn_in_place_angle
        if abs(wrap_angle(direction - pose.theta)) > limit:
            yield from self._turn_to(direction)
            self.planner.reset_command()

    def _follow(self) -> Generator[None, None, None]:
        """Tick the local planner until the goal is reached (then turn to its heading)."""
        ctx, base, cfg = self.ctx, self.base, self.config
        yield from self._face_path()
        while True:
            faults = self._check_faults()
            if faults:
                yield from self._contact(faults)
                continue
            now = ctx.clock.now()
            if self._timed_out(now):
                raise self._fail(FailureKind.EXECUTION, f"not at {self.label} after {self.timeout:g} s", "timeout")
            dt = now - self._last_tick
            if dt <= 0:
                yield  # the clock stands: nothing to do this tick
                continue
            self._last_tick = now
            st = base.state()
            if self._jumped(st, now):
                yield from self._after_jump(st, now)
                continue
            if now >= self._no_dock_until and self._can_dock(st.pose):
                if (yield from self._dock()):
                    return
                continue
            cmd = self.planner.step(st.pose, st.v, st.w, now, dt, self._scan())
            self._log_tick(cmd, st.pose)
            if cmd.status is DwaStatus.GOAL_REACHED:
                yield from brake(ctx, base)
                if (yield from self._turn_to(self.goal.theta)):
                    return
                if self._item_blocked:
                    yield from self._recover("the held item cannot turn to the goal's heading")
                continue  # (or a contact while turning: it backed off and re-planned)
            replanned = cmd.path_blocked and now - self._last_replan >= cfg.replan_interval and \
                self._replan(now, "blocked")
            if replanned:
                pass  # this tick's remaining length was the old path's
            elif self._giving_way(cmd.circles, st.pose):
                self._t_best += dt  # waiting for someone walking by is no standstill
            elif self._stuck(cmd.dwa.remaining, now):
                if (yield from self._view_from_here(st.pose)):
                    return
                yield from self._recover("stuck: no progress along the path")
                continue
            if self._guard is not None and not self._guard.arc_clear(st.pose, cmd.v, cmd.w, self._item_horizon(cmd.v, cmd.w)):
                # the DWA (which sees the footprint only) would sweep the held item into
                # something: stop and turn to the path the way that keeps it clear
                self._emit_item("stopped: the command would sweep the held item into something", st.pose)
                yield from brake(ctx, base)
                yield from self._face_path(force=True)
                self.planner.reset_command()
                if self._stuck(cmd.dwa.remaining, ctx.clock.now()):
                    yield from self._recover("stuck: the held item would sweep into something")
                continue
            base.set_velocity(cmd.v, cmd.w)
            yield

    # ------------------------------------------------------------------ docking
    def _way_clear(self, pose: Pose2D) -> bool:
        """The straight way from ``pose`` to the goal keeps the footprint radius and the
        margin from every costmap obstacle (or as much as the base and the goal have,
        when either has less) and stays out of every non-person circle's safety radius
        (people are the filter's business: they move on). With the radius alone, a dock
        into the lab's depot stop from the east grazed the basket's corner and the
        bumper fired."""
        gx, gy = self.goal.x, self.goal.y
        d = math.hypot(gx - pose.x, gy - pose.y)
        n = max(2, math.ceil(d / (0.5 * self.planner.costmap.resolution)) + 1)
        f = np.linspace(0.0, 1.0, n)[:, None]
        pts = np.array([pose.x, pose.y]) + f * np.array([gx - pose.x, gy - pose.y])
        clear = self.planner.costmap.clearance_at(pts)
        lim = self.config.planner.limits
        need = max(lim.radius, min(lim.radius + self.config.margin, float(clear[0]), float(clear[-1])))
        if np.any(clear[1:] < need - 1e-6):
            return False
        c = self.planner.circles_at(self.ctx.clock.now())
        c = c.select(~c.person)
        if len(c):
            gap = np.hypot(pts[:, None, 0] - c.centres[:, 0], pts[:, None, 1] - c.centres[:, 1]) - c.safety_radii
            return not np.any(gap < 0.0)
        return True

    def _can_dock(self, pose: Pose2D) -> bool:
        """Within ``dock_distance`` of the goal along a clear straight way; with an item
        held, only where that way and the turn at its end keep the item clear (docking
        from the side cut the approach stretch short and pinned the item against the
        crate by the lab's depot)."""
        if math.hypot(self.goal.x - pose.x, self.goal.y - pose.y) > self.config.dock_distance \
                or not self._way_clear(pose):
            return False
        guard = self._guard
        if guard is None or math.hypot(self.goal.x - pose.x, self.goal.y - pose.y) <= ITEM_DOCK_NEAR:
            return True
        return self._stretch_clear(guard, pose.x, pose.y, self.goal.x, self.goal.y,
                                   math.atan2(self.goal.y - pose.y, self.goal.x - pose.x))

    def _dock(self) -> Generator[None, None, bool]:
        """Pure pursuit to the goal along the straight way, heading aligned at the end,
        each command through the CLF-CBF filter against the tracked circles. True when
        docked; False when the way closed (re-planned) or a contact recovery ran."""
        ctx, base = self.ctx, self.base
        start = base.state().pose
        tracker = PathTracker([(start.x, start.y), (self.goal.x, self.goal.y)], self.config.tracker,
                              goal_heading=self.goal.theta)
        self._follow_path([(start.x, start.y), (self.goal.x, self.goal.y)], "dock", ctx.clock.now())
        last = ctx.clock.now()
        # progress: distance to the goal (then heading error while aligning), its best and when
        phase, best, t_best = tracker.phase, math.inf, last
        u = (base.state().v, base.state().w)
        while True:
            faults = self._check_faults()
            if faults:
                yield from self._contact(faults)
                return False
            now = ctx.clock.now()
            if self._timed_out(now):
                raise self._fail(FailureKind.EXECUTION, f"not at {self.label} after {self.timeout:g} s", "timeout")
            dt = now - last
            if dt <= 0:
                yield
                continue
            last = now
            st = base.state()
            if self._jumped(st, now):
                yield from self._after_jump(st, now)
                return False
            self._observe()
            if not self._way_clear(st.pose):
                yield from brake(ctx, base)
                self._replan(now, "dock blocked")
                self.planner.reset_command()
                return False
            v, w, done = tracker.step(st.pose, st.v, st.w, dt)
            if done:
                yield from brake(ctx, base)
                return True
            circles = self.planner.circles_at(now)
            if len(circles) and self.config.planner.use_cbf:
                f = self.planner.safe(st.pose, (v, w), None, circles, u, dt, max(v, 0.0), escape=False)
                self.ctx.emit("nav_tick", pose=_rounded([st.pose.x, st.pose.y, st.pose.theta]), cmd=_rounded([f.v, f.w]),
                              ref=_rounded([v, w]), **barrier_fields(f, circles, st.pose, st.v), active=int(f.active.sum()),
                              infeasible=f.status is QpStatus.INFEASIBLE, status="dock", circles=len(circles))
                v, w = f.v, f.w
            if self._guard is not None and not self._guard.arc_clear(st.pose, v, w, self._item_horizon(v, w)):
                yield from brake(ctx, base)
                if math.hypot(self.goal.x - st.pose.x, self.goal.y - st.pose.y) <= ITEM_DOCK_NEAR:
                    # near enough: align the item-safe way rather than turn to creep the rest
                    self._emit_item("docked short: the last move would sweep the held item into something", st.pose)
                    if (yield from self._turn_to(self.goal.theta)):
                        return True
                    self._no_dock_until = ctx.clock.now() + ITEM_DOCK_PAUSE
                    return False
                self._emit_item("docking stopped: the next move would sweep the held item into something", st.pose)
                self._no_dock_until = now + ITEM_DOCK_PAUSE
                self.planner.reset_command()
                return False
            if (tracker.phase == "align") != (phase == "align"):
                # the measure of progress changes (distance, then heading); turning to the
                # goal and driving to it share one: a tracker swapping between them as
                # the filter held it restarted the count for ever (90 s timeouts)
                best, t_best = math.inf, now
            phase = tracker.phase
            progress = (abs(wrap_angle(self.goal.theta - st.pose.theta)) if phase == "align"
                        else math.hypot(self.goal.x - st.pose.x, self.goal.y - st.pose.y))
            if progress < best - DOCK_PROGRESS[phase == "align"]:
                best, t_best = progress, now
            elif self.planner.people_wait.update(circles.people, (st.pose.x, st.pose.y), now,
                                                 abs(u[0]) <= WAIT_SPEED):
                # giving way to people, within the patience; standing is judged by docking's
                # own last command (the planner's is the DWA's from before docking began,
                # and a fast one there never let the patience run out)
                t_best += dt
            elif now - t_best > self.config.planner.dwa.stuck_time:
                yield from brake(ctx, base)
                if (yield from self._view_from_here(st.pose)):
                    return True
                if self._leave_zones(self._inflated(now), now):  # the obstacle turned out bigger
                    self._replan(now, "goal moved")
                else:
                    yield from self._recover("docking held back by the safety filter")
                self.planner.reset_command()
                return False
            u = (v, w)
            base.set_velocity(v, w)
            yield

    def _view_from_here(self, pose: Pose2D) -> Generator[None, None, bool]:
        """A drive to a place to look from (``view_slack`` > 0), stuck within
        ``view_slack`` of the place asked for (not of a goal moved out of an obstacle's
        zone: the two together took a look 0.9 m from it), ends here: brake, turn to the
        goal's heading, True (``nav_view_short``). In the UR platforms' crowd rows people
        walking loops through a search location or a marker's viewpoint kept the 0.81 m
        base 0.2-0.8 m short of it for the whole drive, and the search or the approach
        failed."""
        short = math.hypot(self._asked.x - pose.x, self._asked.y - pose.y)
        if short > self.config.view_slack:
            return False
        yield from brake(self.ctx, self.base)
        self.ctx.emit("nav_view_short", label=self.label, goal=_rounded([self.goal.x, self.goal.y]),
                      pose=_rounded([pose.x, pose.y, pose.theta]), short=round(short, 3), node=self.ctx.node_path)
        log.info("%s: stuck %.2f m short of it: looking from here", self.label, short)
        yield from self._turn_to(self.goal.theta)
        return True

    # ------------------------------------------------------------------ motions
    def _turn_to(self, target: float, *, rate: float | None = None) -> Generator[None, None, bool]:
        """Turn in place to heading ``target`` [rad] within the heading tolerance
        (observing scans on the way); ``rate`` [rad/s] caps the turn rate. With an item
        held, the turn goes the way round that keeps it clear (:meth:`_item_way`). False
        when a contact cut the turn short (the contact recovery ran), or when neither way
        keeps the item clear (no turn; ``_item_blocked`` set)."""
        for _ in range(2):
            angle = yield from self._item_way(target)
            self._item_blocked = angle is None
            if angle is None:
                return False
            if (yield from self._turn_by(angle, rate)):
                return True
            if not self._item_blocked:
                return False  # a contact: its recovery ran
            # something walked into the item's sweep and stayed: the other way round, or
            # back off (:meth:`_item_way`), from where the turn stopped
        return False

    def _turn_by(self, angle: float, rate: float | None) -> Generator[None, None, bool]:
        """Turn in place by ``angle`` [rad] (signed, counted as the base turns, so more
        than half a turn goes the way asked); see :meth:`_turn`."""
        turned, last = [0.0], [self.base.state().pose.theta]

        def left(theta: float) -> float:
            turned[0] += wrap_angle(theta - last[0])
            last[0] = theta
            return angle - turned[0]

        return (yield from self._turn(left, rate))

    def _item_way(self, target: float) -> Generator[None, None, float | None]:
        """The signed turn [rad] to heading ``target``: the shorter way, or, with an item
        held that the shorter way would sweep into something (:class:`ItemGuard`), the
        longer way when that keeps it clear; when neither does, back off up to
        :data:`ITEM_BACK_OFF` where there is room and look again; failing that None
        (logged ``nav_item``): the base does not turn."""
        guard = self._guard
        angle = wrap_angle(target - self.base.state().pose.theta)
        if guard is None or abs(angle) <= self.config.heading_tolerance:
            return angle
        for attempt in range(2):
            pose = self.base.state().pose
            angle = wrap_angle(target - pose.theta)
            if self._sweep_clear(pose, angle):
                return angle
            other = angle - math.copysign(2.0 * math.pi, angle)
            if self._sweep_clear(pose, other):
                self._emit_item("turn the other way round", pose)
                return other
            room = self._room_behind(pose, ITEM_BACK_OFF) if attempt == 0 else 0.0
            if room <= 0.02:
                break
            self._emit_item(f"back off {room:.2f} m to turn", pose)
            yield from self._back_off(room)
        pose = self.base.state().pose
        self._emit_item("no turn: it would sweep the held item into something either way", pose)
        log.info("%s: turning to %.2f rad would sweep the held item into something either way", self.label, target)
        return None

    def _item_horizon(self, v: float, w: float) -> float:
        """[s] how far ahead command ``(v, w)`` is checked for the held item: the time the
        base needs to stop from it at its accelerations, plus :data:`ITEM_HORIZON`."""
        lim = self.config.planner.limits
        return max(abs(v) / lim.accel_v, abs(w) / lim.accel_w) + ITEM_HORIZON

    def _emit_item(self, what: str, pose: Pose2D) -> None:
        """Log what the held item made the drive do (``nav_item``)."""
        self.ctx.emit("nav_item", what=what, label=self.label, pose=_rounded([pose.x, pose.y, pose.theta]),
                      node=self.ctx.node_path)

    def _turn(self, error: Callable[[float], float], rate: float | None) -> Generator[None, None, bool]:
        """Turn in place until ``error(theta)`` [rad] is within the heading tolerance: the
        fastest turn rate that still stops there, within the limits (and ``rate``). False
        when a contact cut it short (the contact recovery ran), or, with an item held, when
        something came into the item's sweep ahead and stayed (``_item_blocked`` set).
        With an item held the sweep of the rest of the turn is checked on every tick
        against the newest scan (:meth:`_sweep_clear`); when it is not clear the base
        stops and holds, up to :data:`ITEM_TURN_HOLD` seconds, and turns on once it is
        (a person walked into the sweep of the turn after a pick, and the item touched
        them, when the turn was checked only as it began)."""
        ctx, base = self.ctx, self.base
        lim = self.config.planner.limits
        w_max = lim.max_w if rate is None else min(lim.max_w, rate)
        last = ctx.clock.now()
        held: float | None = None  # [s] when the turn stopped for the item's sweep
        self._item_blocked = False
        while True:
            faults = self._check_faults()
            if faults:
                yield from self._contact(faults)
                return False
            st = base.state()
            err = error(st.pose.theta)
            now = ctx.clock.now()
            if abs(err) <= self.config.heading_tolerance:
                yield from brake(ctx, base)
                return True
            if self._timed_out(now):
                raise self._fail(FailureKind.EXECUTION, f"not at {self.label} after {self.timeout:g} s", "timeout")
            dt = max(now - last, 1e-3)
            last = now
            self._observe()
            if not self._sweep_clear(st.pose, err):
                if held is None:
                    held = now
                    self._emit_item("turn held: something came into the held item's sweep", st.pose)
                if now - held > ITEM_TURN_HOLD:
                    yield from brake(ctx, base)
                    self._item_blocked = True
                    return False
                dw = lim.accel_w * dt
                base.set_velocity(0.0, max(st.w - dw, min(st.w + dw, 0.0)))
                yield
                continue
            held = None
            w_stop = math.sqrt(2.0 * lim.accel_w * 0.8 * abs(err))
            w_des = math.copysign(max(min(w_max, w_stop), 0.1), err)
            dw = lim.accel_w * dt
            base.set_velocity(0.0, max(st.w - dw, min(st.w + dw, w_des)))
            yield

    def _sweep_clear(self, pose: Pose2D, angle: float) -> bool:
        """Whether a turn in place by ``angle`` [rad] (signed, may exceed pi) from
        ``pose`` keeps the held item clear of the costmap (:meth:`ItemGuard.turn_clear`)
        and of the tracked people (their covering circles, each moved at its velocity to
        when the base passes each heading at full turn rate), as :class:`ItemGuard` judges
        it: no closer than ``margin``, or than at the start; True without an item."""
        guard = self._guard
        if guard is None:
            return True
        if not guard.turn_clear(pose, angle):
            return False
        people = self.planner.circles_at(self.ctx.clock.now()).people
        if not len(people):
            return True
        n = max(1, math.ceil(abs(angle) / guard.TURN_STEP))
        f = np.linspace(0.0, 1.0, n + 1)
        pts = guard.item.in_map(np.stack([np.full(n + 1, pose.x), np.full(n + 1, pose.y), pose.theta + f * angle],
                                         axis=1))  # (n + 1, k, 2)
        t = f * abs(angle) / max(self.config.planner.limits.max_w, 1e-6)
        centres = people.centres[None] + t[:, None, None] * people.velocities[None]  # (n + 1, m, 2)
        d = np.linalg.norm(pts[:, :, None, :] - centres[:, None, :, :], axis=-1) - people.radii - guard.item.radius
        gap = d.min(axis=(1, 2))  # per heading along the turn
        return not bool(np.any((gap[1:] < guard.margin) & (gap[1:] < gap[0] - 1e-3)))

    def _room_behind(self, pose: Pose2D, distance: float) -> float:
        """How far [m] (up to ``distance``) the base can back straight off from ``pose``
        with the costmap's clearance and every circle's safety radius kept
        (:meth:`LocalPlanner.room_behind`)."""
        return self.planner.room_behind(pose, distance, self.ctx.clock.now())

    def _back_off(self, distance: float, *, pressed: bool = False) -> Generator[None, None, float]:
        """Drive straight back ``distance`` [m] at :data:`BACK_OFF_SPEED` (observing
        scans); ``pressed``: a contact sensor is still reporting, which is expected while
        the base backs away from what it touched. Returns the distance covered [m]."""
        ctx, base = self.ctx, self.base
        start = base.state().pose
        t0 = ctx.clock.now()
        while True:
            st = base.state()
            faults = st.faults
            other = frozenset(f for f in faults if not is_contact(f))
            if other or (faults and not pressed):
                self._check_faults()  # raises for another fault
                yield from self._contact(faults)
                return start.distance_to(base.state().pose)
            done = start.distance_to(st.pose)
            now = ctx.clock.now()
            if faults and now - t0 > CONTACT_CLEAR_TIME and done < 0.01:
                raise self._fail(FailureKind.EXECUTION,
                                 f"base fault on the way to {self.label}: {', '.join(sorted(faults))} still reported "
                                 f"{CONTACT_CLEAR_TIME:g} s after the contact: the base cannot back off",
                                 f"base fault: {', '.join(sorted(faults))}")
            if done >= distance - 0.005 or self._timed_out(now):
                yield from brake(ctx, base)
                return done
            left = distance - done
            v = min(BACK_OFF_SPEED, math.sqrt(2.0 * self.config.planner.limits.accel_v * 0.5 * left))
            base.set_velocity(-max(v, 0.02), 0.0)
            self._observe()
            yield

    # ------------------------------------------------------------------ recoveries
    def _recover(self, why: str) -> Generator[None, None, None]:
        """Brake, turn once round, back off, re-plan; fail when the recoveries are spent."""
        ctx = self.ctx
        self.recoveries += 1
        if self.recoveries > self.config.recoveries:
            inside = self._goal_guarded()
            if inside is not None:
                raise self._fail(FailureKind.PLANNING,
                                 f"no path to {self.label}: the goal is {inside:.2f} m from an obstacle the map does "
                                 f"not show, inside the zone the safety filter keeps the base out of", "blocked")
            # no way left even if everyone the re-plans leave out as people stays where
            # they are (a tracked circle taken for a person can be furniture whose
            # visible side wandered as the base drove by): blocked, a planning failure
            if self._no_way or self._plan_on(self._inflated(self.ctx.clock.now(), everyone=True),
                                             self.base.state().pose, "blocked", log_none=False) is None:
                raise self._fail(FailureKind.PLANNING,
                                 f"no path to {self.label}: blocked by obstacles the map does not show "
                                 f"({self.config.recoveries} recoveries, {self.replans} re-plans)", "blocked")
            raise self._fail(FailureKind.EXECUTION,
                             f"stuck on the way to {self.label} after {self.config.recoveries} recoveries "
                             f"(rotate, back off, re-plan): {why}", "stuck")
        pose = self.base.state().pose
        if why.startswith("stuck"):
            self._widen = STUCK_WIDEN
        ctx.emit("nav_recovery", attempt=self.recoveries, of=self.config.recoveries, why=why,
                 pose=_rounded([pose.x, pose.y, pose.theta]), node=ctx.node_path)
        log.info("%s: recovery %d of %d (%s)", self.label, self.recoveries, self.config.recoveries, why)
        yield from brake(ctx, self.base)
        here = self.base.state().pose
        room_round = float(self.planner.costmap.clearance_at(np.array([[here.x, here.y]]))[0]) - \
            self.config.planner.limits.radius
        if room_round >= RECOVERY_TURN_ROOM and self._sweep_clear(here, 2.0 * math.pi):
            yield from self._turn_by(2.0 * math.pi, None)
        else:
            log.info("%s: recovery without the turn: %.2f m round the footprint", self.label, room_round)
        room = self._room_behind(self.base.state().pose, self.config.back_off)
        if room > 0.02:
            yield from self._back_off(room)
        self._restart_progress(ctx.clock.now())
        self._replan(ctx.clock.now(), "recovery")
        self.planner.reset_command()

    def _contact(self, faults: frozenset[str]) -> Generator[None, None, None]:
        """Stop, pin what was felt in the costmap, back off, re-plan (module docstring)."""
        ctx, base = self.ctx, self.base
        self.contacts += 1
        names = ", ".join(sorted(faults))
        if self.contacts > self.config.recoveries:
            raise self._fail(FailureKind.EXECUTION,
                             f"base fault on the way to {self.label}: {names} ({self.contacts} contacts)",
                             f"base fault: {names}")
        base.stop()
        if not (base.state().faults & BLIND_FAULTS):
            yield from brake(ctx, base)
        pose = base.state().pose
        pts = contact_points(pose, faults, self.config.planner.limits.radius)
        # a contact the map explains (its arc reaches a mapped obstacle) is no news, as
        # for the lidar's hits: a bump against the depot's low basket pinned marks that a
        # held item then took for something tall, blocking the stop for good
        cm = self.planner.costmap
        if np.any(cm.static.clearance_at(pts) <= cm.config.static_tolerance):
            pts = pts[:0]
        cm.pin(pts)
        ctx.emit("nav_contact", faults=sorted(faults), attempt=self.contacts, of=self.config.recoveries,
                 pose=_rounded([pose.x, pose.y, pose.theta]), marked=_rounded(pts.tolist()), node=ctx.node_path)
        log.warning("%s: %s at (%.2f, %.2f): backing off and re-planning", self.label, names, pose.x, pose.y)
        yield from self._back_off(self.config.back_off, pressed=True)
        self._restart_progress(ctx.clock.now())
        self._replan(ctx.clock.now(), "contact")
        self.planner.reset_command()
