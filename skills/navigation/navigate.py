"""Base navigation skills: grid A* on the robot's occupancy map inflated by its radius,
then pure-pursuit path tracking within velocity and acceleration limits
(:mod:`mmexec.skills.navigation`); turning in place and backing off in a straight line.
With ``nav.local_planner: true`` the A* path is followed by the local planner instead: the
DWA on the rolling lidar costmap and the CLF-CBF safety filter, with re-plans, recoveries
and the bumper/cliff contact recovery (:mod:`mmexec.skills.navigation.local_drive`; it
needs a lidar).

Skills: ``navigate`` (to a named base pose or x/y/theta) and ``back_off`` (straight
backwards). The building blocks other skills use: :func:`drive_path`, :func:`rotate_by`,
:func:`back_off_by` and :func:`costmap`. Every motion runs the base's motion loop
(:func:`mmexec.skills.primitives.motion_loop`: a fault or a timeout brakes and fails, a
cancel brakes). ``drive_path`` emits the seed's base states as ``base_status`` events:
``to_goal`` when a path was found and the base starts moving, ``goal_ok`` on arrival,
``goal_fail`` when there is no path or the motion failed, ``idle`` once the base is at
rest again.

Settings: the profile's ``nav:`` section (:class:`NavSettings`: speed and acceleration
limits, the map's extra inflation, goal tolerances, the default timeout, and the
stand-off settings ``approach`` reads; the local planner's switch and its recovery
settings). World model: the inflated map under ``nav.costmap``; the path being followed
under ``nav.path`` (``[[x, y], ...]`` in ``map``, for the live console; empty between
drives), tracked people under ``nav.people`` (local planner).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator, Mapping
from dataclasses import dataclass, replace
from typing import Any

from mmexec.config.yamlload import Mark, Problems, mark_of
from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import Base, BaseState, Pose2D
from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillContext,
    SkillFailure,
    SkillGen,
    skill,
)
from mmexec.skills.navigation import (
    CostMap,
    PathTracker,
    TrackerConfig,
    inflate,
    plan_path,
    simplify_path,
)
from mmexec.skills.navigation.dwa import DwaConfig
from mmexec.skills.navigation.limits import BaseLimits
from mmexec.skills.navigation.local_drive import (
    WORLD_PATH,
    LocalDrive,
    LocalDriveConfig,
    local_planner,
)
from mmexec.skills.navigation.local_planner import LocalPlannerConfig
from mmexec.skills.poses import base_pose
from mmexec.skills.primitives import Step, motion_loop
from mmexec.skills.profile import PROFILE, declare_settings, setting

__all__ = [
    "WORLD_COSTMAP",
    "NavSettings",
    "back_off",
    "back_off_by",
    "base_status",
    "costmap",
    "drive_path",
    "nav_margin",
    "nav_settings",
    "navigate",
    "rotate_by",
]

log = logging.getLogger(__name__)

WORLD_COSTMAP = "nav.costmap"


# --------------------------------------------------------------------------- profile


@dataclass(frozen=True)
class NavSettings:
    """The ``nav:`` section of a robot profile: base motion (speed limits and
    accelerations, extra inflation of the map, goal tolerances, pure pursuit lookahead,
    the default navigation timeout, the goal search radius) and the stand-off in front of
    a marker that ``approach`` drives to (see each setting's doc)."""

    max_v: float = setting(0.5, unit="m/s", gt=0, doc="linear speed limit")
    max_w: float = setting(1.5, unit="rad/s", gt=0, doc="angular speed limit")
    accel_v: float = setting(0.8, unit="m/s^2", gt=0, doc="linear acceleration limit")
    accel_w: float = setting(3.0, unit="rad/s^2", gt=0, doc="angular acceleration limit")
    margin: float = setting(0.03, unit="m", ge=0, doc="inflation of the map on top of the base's footprint radius")
    goal_tolerance: float = setting(0.04, unit="m", gt=0, doc="position tolerance at the goal")
    heading_tolerance: float = setting(0.04, unit="rad", gt=0, doc="heading tolerance at the goal")
    lookahead: float = setting(0.35, unit="m", gt=0, doc="pure pursuit lookahead")
    timeout: float = setting(90.0, unit="clock s", gt=0, doc="default navigation timeout")
    goal_search: float = setting(0.3, unit="m", ge=0, doc=(
        "a goal that an obstacle covers (in the inflated map) is moved to the nearest free point within "
        "this distance, like a global planner's goal tolerance (0: fail instead)"))
    approach_distances: list[float] = setting(
        [0.35, 0.45, 0.55], unit="m", gt=0,
        doc="approach: stand-off distances from the marker face, tried in order (a recovery indexes them)")
    refine_at: float = setting(0.8, unit="m", gt=0, doc=(
        "approach: the base's stand-off from the marker face where it looks again when the estimate was "
        "seen from afar (a wrist camera ahead of the base needs it farther than a head camera does)"))
    redetect_at_standoff: bool = setting(False, doc=(
        "approach: look at the marker once more from the stand-off pose reached and keep that estimate "
        "(for a pick)"))
    local_planner: bool = setting(False, doc=(
        "follow the A* path with the DWA local planner on the rolling lidar costmap and the CLF-CBF safety "
        "filter (re-plans around what the map does not show, recovers when stuck, backs off from a bumper or "
        "cliff contact; needs a lidar); false: pure pursuit on the static map"))
    replan_interval: float = setting(1.0, unit="clock s", gt=0, doc=(
        "local planner: least time between two global re-plans while the path ahead is blocked"))
    recoveries: int = setting(3, ge=0, doc=(
        "local planner: recoveries when stuck (turn once round, back off, re-plan), and bumper or cliff "
        "contacts, before a drive fails"))
    recovery_back_off: float = setting(0.2, unit="m", ge=0, doc=(
        "local planner: how far a recovery or a contact backs off (less where the costmap leaves less room)"))
    safety_filter: bool = setting(True, doc=(
        "local planner: pass every command through the CLF-CBF safety filter; false sends the DWA's command "
        "unfiltered (for comparisons only: what the filter buys)"))

    def validate(self) -> list[str]:
        """Checks that relate several settings (single-value ranges are declared)."""
        if not self.approach_distances:
            return ["approach_distances: expected a non-empty list of distances > 0 m"]
        return []


nav_settings = declare_settings("nav", NavSettings, package=__name__,
                                doc="base navigation: speed limits, inflation, tolerances, stand-offs")


def nav_margin(profile: Mapping[str, Any]) -> float:
    """The margin [m] navigation adds to the base's footprint radius when it inflates the
    map: ``nav.margin``, or its default when the profile has no (valid) nav section
    (for ``mmexec validate``, which reports the section's problems itself)."""
    raw = profile.get("nav")
    if raw is not None:
        out = PROFILE.bind_section("nav", raw, mark_of(raw, Mark("<profile>", 1, 1)), Problems())
        if isinstance(out, NavSettings):
            return out.margin
    return NavSettings().margin


def base_status(ctx: SkillContext, status: str, **fields: Any) -> None:
    """Emit the seed's base state: ``to_goal``, ``goal_ok``, ``goal_fail`` or ``idle``."""
    ctx.emit("base_status", status=status, node=ctx.node_path, **fields)


# --------------------------------------------------------------------------- motions


def costmap(ctx: SkillContext) -> CostMap:
    """The robot's occupancy map inflated by the base radius plus the profile's margin,
    cached in the world model until the map or the radius changes."""
    robot = ctx.robot
    if robot.occupancy is None:
        raise SkillFailure(FailureKind.PRECONDITION,
                           "navigation needs a map: this robot has no occupancy grid (robot.map in the config)")
    base = robot.base
    assert base is not None
    margin = nav_settings(ctx).margin
    key = (id(robot.occupancy), base.radius, margin)
    cached = ctx.world.get(WORLD_COSTMAP)
    if cached is not None and cached[0] == key and cached[1].grid is robot.occupancy:
        return cached[1]
    cm = inflate(robot.occupancy, base.radius, margin)
    ctx.world[WORLD_COSTMAP] = (key, cm)
    return cm


def _tracker_config(ctx: SkillContext, base: Base, max_v: float | None) -> TrackerConfig:
    """The profile's limits and tolerances, within the base's own limits (``max_v``
    [m/s]: a lower speed limit for this motion)."""
    nav = nav_settings(ctx)
    return TrackerConfig(
        max_v=min(max_v or nav.max_v, base.max_linear), max_w=min(nav.max_w, base.max_angular),
        accel_v=min(nav.accel_v, base.max_linear_accel), accel_w=min(nav.accel_w, base.max_angular_accel),
        lookahead=nav.lookahead, goal_tolerance=nav.goal_tolerance, heading_tolerance=nav.heading_tolerance,
    )


def local_drive_config(ctx: SkillContext, base: Base, max_v: float | None) -> LocalDriveConfig:
    """The local planner's configuration from the profile's ``nav:`` section, within the
    base's own limits (``max_v`` [m/s]: a lower speed limit for this motion): the
    footprint radius, the margin, the goal tolerance of the DWA, the recovery settings."""
    nav = nav_settings(ctx)
    limits = BaseLimits(radius=base.radius, max_v=min(max_v or nav.max_v, base.max_linear),
                        max_w=min(nav.max_w, base.max_angular), accel_v=min(nav.accel_v, base.max_linear_accel),
                        accel_w=min(nav.accel_w, base.max_angular_accel))
    planner = LocalPlannerConfig.for_base(limits, nav.margin, dwa=DwaConfig(goal_tolerance=nav.goal_tolerance),
                                          use_cbf=nav.safety_filter)
    return LocalDriveConfig(planner=planner, margin=nav.margin, tracker=_tracker_config(ctx, base, max_v),
                            replan_interval=nav.replan_interval,
                            recoveries=nav.recoveries, back_off=nav.recovery_back_off,
                            heading_tolerance=nav.heading_tolerance, goal_search=nav.goal_search,
                            pose_jump=POSE_JUMP, jump_replans=MAX_JUMP_REPLANS)


def drive_path(ctx: SkillContext, goal: Pose2D, label: str, *, timeout: float, max_v: float | None = None,
               path: list[tuple[float, float]] | None = None, viewpoint: bool = False,
               view_short: float | None = None) -> Generator[None, None, Pose2D]:
    """Plan (A*, unless ``path`` is given) from the base's pose to ``goal`` and track the
    path, ending at ``goal.theta``; with ``nav.local_planner`` follow it with the local
    planner (:class:`~mmexec.skills.navigation.local_drive.LocalDrive`). Emits base states
    and publishes the path under ``nav.path``. Failures: PLANNING "no path to LABEL";
    EXECUTION on a base fault (bumper, cliff, link; with the local planner only once its
    contact recoveries are spent) or after ``timeout`` clock seconds; PRECONDITION for the
    local planner without a lidar, and "not localised" while the robot's localiser has not
    converged (``BaseState.localised``; docs/localization.md). When the localised pose
    jumps on the way (the localiser found the robot elsewhere, e.g. after a kidnap), the
    plain drive brakes and plans again from the new pose (``nav_replan``, at most
    :data:`MAX_JUMP_REPLANS` times). Cancellation brakes the base before re-raising.
    ``viewpoint``: the goal is a place to look from, which the local planner may move out
    of an unmapped obstacle's zone (LocalDriveConfig.zone_goal_search), and may look
    from up to ``view_short`` [m] (default :data:`VIEW_SHORT`) short of it when stuck
    there (people in the way; LocalDriveConfig.view_slack). Returns the pose reached."""
    base = ctx.robot.base
    if base is None:
        raise SkillFailure(FailureKind.PRECONDITION, "navigation needs a base, and this robot has none")
    cm = costmap(ctx)
    _require_localised(ctx, base, label)
    if nav_settings(ctx).local_planner:
        lidar = ctx.robot.lidar
        if lidar is None:
            raise SkillFailure(FailureKind.PRECONDITION,
                               "nav.local_planner needs a lidar, and this robot has none (set it false in the profile)")
        if path is None:
            goal = _free_goal(ctx, cm, goal, label)
        config = local_drive_config(ctx, base, max_v)
        if viewpoint:
            config = replace(config, zone_goal_search=VIEWPOINT_SLACK,
                             view_slack=VIEW_SHORT if view_short is None else view_short)
        drive = LocalDrive(ctx, base, lidar, goal, label, config=config, static=cm,
                           timeout=timeout, path=path, status=base_status)
        return (yield from drive.run())
    if path is None:
        goal = _free_goal(ctx, cm, goal, label)
    given = path
    t_end = ctx.clock.now() + timeout
    try:
        for replan in range(MAX_JUMP_REPLANS + 1):
            start = base.state().pose
            path = given if given is not None and replan == 0 else _plan(ctx, cm, start, goal, label)
            # the grid path runs between cell centres: start and end exactly where the base and goal are
            path = [(start.x, start.y)] + list(path[1:-1]) + [(goal.x, goal.y)] if len(path) > 1 else [(goal.x, goal.y)]
            ctx.world[WORLD_PATH] = [[float(x), float(y)] for x, y in path]
            tracker = PathTracker(path, _tracker_config(ctx, base, max_v), goal_heading=goal.theta)
            if replan == 0:
                base_status(ctx, "to_goal", goal=[round(goal.x, 3), round(goal.y, 3), round(goal.theta, 3)],
                            label=label)
            jumped = yield from _track(ctx, base, tracker, label, timeout, t_end, replan < MAX_JUMP_REPLANS)
            if jumped is None:
                break
            if math.isnan(jumped):  # the localiser lost the map on the way: stopped
                base_status(ctx, "goal_fail", reason="not localised")
                raise SkillFailure(FailureKind.EXECUTION, f"lost localisation on the way to {label}: the scans no "
                                   "longer match the map at the estimated pose (stopped; run 'localize')")
            ctx.emit("nav_replan", label=label, reason="the localised pose jumped", jump=round(jumped, 3),
                     node=ctx.node_path)
        reached = base.state().pose
        base_status(ctx, "goal_ok", pose=[round(reached.x, 3), round(reached.y, 3), round(reached.theta, 3)])
        return reached
    finally:
        ctx.world[WORLD_PATH] = []
        base_status(ctx, "idle")


#: a pose change between two ticks this much larger than the base's motion could explain
#: ([m], [rad]) is the localiser correcting the pose (a re-localisation after a kidnap):
#: the path, planned from where the base was believed to be, is planned again
POSE_JUMP = (0.15, 0.15)
#: re-plans after pose jumps within one drive
MAX_JUMP_REPLANS = 3

#: [m] how far the local planner may move a viewpoint goal out of an unmapped obstacle's
#: zone (``drive_path(..., viewpoint=True)``: the search's locations)
VIEWPOINT_SLACK = 0.6
#: [m] a viewpoint drive stuck this near its goal looks from where it stands (the local
#: planner: ``drive_path(..., viewpoint=True)``; the search's locations). Search locations
#: sit near the camera's detection range of the boards they look at: from 0.78 m short of
#: the lab's search location 1 the LoCoBot's search took 113 s longer (LoCoBot lab crowd
#: seed 2904366694)
VIEW_SHORT = 0.4
#: [m] the same for the approach's refining viewpoint, where the marker is known and near
#: (a look from farther refines less, and the estimate is kept when it does not): UR5e lab
#: crowd seed 269668801 looked 0.79 m short of the marker 4 viewpoint and delivered 93 s
#: sooner than when it waited there
REFINE_SHORT = 0.8
#: [m] backing off (:func:`back_off_by`) keeps this much beyond a tracked person's safety
#: radius (the sim's people keep 0.3 m from the footprint; the arm can reach past it)
BACK_OFF_PERSON_GAP = 0.3


def _require_localised(ctx: SkillContext, base: Base, label: str) -> None:
    """PRECONDITION failure when the localiser runs and has not converged: a drive on the
    map from a pose the filter does not know (run ``localize`` first)."""
    st = base.state()
    if st.localised:
        return
    c = st.covariance
    sd = f" (position spread {math.sqrt(max(c[0][0], c[1][1])):.2f} m)" if c is not None else ""
    base_status(ctx, "goal_fail", reason="not localised")
    base_status(ctx, "idle")
    raise SkillFailure(FailureKind.PRECONDITION,
                       f"not localised: the localiser has not converged{sd}; not driving to {label} "
                       "(run 'localize' first)")


def _plan(ctx: SkillContext, cm: CostMap, start: Pose2D, goal: Pose2D, label: str) -> list[tuple[float, float]]:
    """The simplified A* path from ``start`` to ``goal``; PLANNING failure when none."""
    path = plan_path(cm, (start.x, start.y), (goal.x, goal.y))
    if path is None:
        base_status(ctx, "goal_fail", goal=[goal.x, goal.y, goal.theta], reason="no path")
        raise SkillFailure(FailureKind.PLANNING, f"no path to {label} ({goal.x:.2f}, {goal.y:.2f})")
    return simplify_path(cm, path)


def _track(ctx: SkillContext, base: Base, tracker: PathTracker, label: str, timeout: float, t_end: float,
           watch_jumps: bool) -> Generator[None, None, float | None]:
    """Follow ``tracker``'s path to the end (None), or, with ``watch_jumps``, until the
    localised pose jumps (:data:`POSE_JUMP`): brake and return the jump [m]; brake and
    return NaN when the base stops being localised."""
    last = ctx.clock.now()
    prev: BaseState | None = None
    jump: float | None = None

    def step(st: BaseState, now: float) -> tuple[float, float] | Step:
        """The tracker's command, once per clock step (none while the clock stands)."""
        nonlocal last, prev, jump
        dt = now - last
        if dt <= 0:
            return Step.HOLD
        last = now
        if not st.localised:
            jump = math.nan
            return Step.ARRIVED
        if watch_jumps and prev is not None:
            moved = prev.pose.distance_to(st.pose) - max(abs(prev.v), abs(st.v)) * dt
            turned = abs(wrap_angle(st.pose.theta - prev.pose.theta)) - max(abs(prev.w), abs(st.w)) * dt
            if moved > POSE_JUMP[0] or turned > POSE_JUMP[1]:
                jump = prev.pose.distance_to(st.pose)
                return Step.ARRIVED
        prev = st
        v, w, done = tracker.step(st.pose, st.v, st.w, dt)
        return Step.ARRIVED if done else (v, w)

    yield from motion_loop(ctx, base, step, fault=f"base fault on the way to {label}", deadline=t_end,
                           timeout=f"not at {label} after {timeout:g} s",
                           on_failure=lambda reason: base_status(ctx, "goal_fail", reason=reason))
    return jump


def _free_goal(ctx: SkillContext, cm: CostMap, goal: Pose2D, label: str) -> Pose2D:
    """``goal``, or the nearest free point within ``nav.goal_search`` when the inflated map
    ``cm`` covers it (``goal_adjusted``); PLANNING failure when neither is free."""
    search = nav_settings(ctx).goal_search
    free = cm.nearest_free(goal.x, goal.y, search) if search > 0 else None
    if free is not None and (free[0], free[1]) != (goal.x, goal.y):
        moved = Pose2D(free[0], free[1], goal.theta)
        log.info("%s: goal (%.2f, %.2f) is in collision; using (%.2f, %.2f), %.2f m away",
                 label, goal.x, goal.y, moved.x, moved.y, goal.distance_to(moved))
        ctx.emit("goal_adjusted", label=label, goal=[round(goal.x, 3), round(goal.y, 3)],
                 used=[round(moved.x, 3), round(moved.y, 3)], shift=round(goal.distance_to(moved), 3),
                 node=ctx.node_path)
        goal = moved
    if not cm.is_free(goal.x, goal.y):
        base_status(ctx, "goal_fail", goal=[goal.x, goal.y, goal.theta], reason="goal in collision")
        base_status(ctx, "idle")
        raise SkillFailure(FailureKind.PLANNING,
                           f"no path to {label}: goal ({goal.x:.2f}, {goal.y:.2f}) is in collision or off the map"
                           + (f", and no free point lies within {search:g} m" if search > 0 else ""))
    return goal


def rotate_by(ctx: SkillContext, angle: float, *, timeout: float = 20.0) -> Generator[None, None, Pose2D]:
    """Turn in place by ``angle`` [rad] (negative: clockwise) on the odometry heading,
    within the profile's angular speed and acceleration limits; brake to rest at the end.
    EXECUTION failure on a base fault or after ``timeout`` clock seconds."""
    base = ctx.robot.base
    assert base is not None
    cfg = _tracker_config(ctx, base, None)
    target = wrap_angle(base.state().pose.theta + angle)
    t_end = ctx.clock.now() + timeout
    w_cmd = base.state().w
    last = ctx.clock.now()

    def step(st: BaseState, now: float) -> tuple[float, float] | Step:
        """Ramp the turn rate (within the angular acceleration) to the fastest that still
        stops at the target."""
        nonlocal w_cmd, last
        err = wrap_angle(target - st.pose.theta)
        if abs(err) <= cfg.heading_tolerance:
            return Step.ARRIVED
        dt = max(now - last, 1e-3)
        last = now
        w_stop = math.sqrt(2.0 * cfg.accel_w * 0.8 * abs(err))
        w_des = math.copysign(max(min(cfg.max_w, w_stop), 0.1), err)
        dw = cfg.accel_w * dt
        w_cmd = max(w_cmd - dw, min(w_cmd + dw, w_des))
        return 0.0, w_cmd

    yield from motion_loop(ctx, base, step, fault="base fault while turning", deadline=t_end,
                           timeout=f"turn of {math.degrees(angle):.0f} deg not done after {timeout:g} s")
    return base.state().pose


def back_off_by(ctx: SkillContext, distance: float, *, speed: float = 0.2,
                timeout: float = 15.0) -> Generator[None, None, Pose2D]:
    """Drive straight backwards ``distance`` [m] on odometry, within the acceleration
    limit; brake to rest at the end. With a map, and starting from a free pose, only as
    far as the line behind stays free in the inflated map (the base did not necessarily
    arrive along it: an obstacle beside the stand-off can lie behind it), logged as
    ``back_off_shortened``. ``speed`` [m/s] is the top speed. EXECUTION failure on a base
    fault or after ``timeout`` clock seconds. Returns the pose reached."""
    base = ctx.robot.base
    assert base is not None
    start = base.state().pose
    if ctx.robot.occupancy is not None and distance > 0:
        cm = costmap(ctx)
        if cm.is_free(start.x, start.y):
            ds, free, d = 0.5 * cm.resolution, 0.0, 0.0
            while d < distance:
                d = min(distance, d + ds)
                if not cm.is_free(start.x - d * math.cos(start.theta), start.y - d * math.sin(start.theta)):
                    break
                free = d
            if free < distance:
                ctx.emit("back_off_shortened", asked=round(distance, 3), used=round(free, 3), node=ctx.node_path)
                distance = free
    if distance > 0 and nav_settings(ctx).local_planner and ctx.robot.lidar is not None \
            and ctx.robot.occupancy is not None:
        room = _lidar_room_behind(ctx, base, start, distance)
        if room < distance:
            ctx.emit("back_off_shortened", asked=round(distance, 3), used=round(room, 3), by="lidar",
                     node=ctx.node_path)
            distance = room
    if distance <= 0.005:
        return start
    t_end = ctx.clock.now() + timeout

    def step(st: BaseState, _now: float) -> tuple[float, float] | Step:
        """Backwards, slowing down (within the acceleration) to stop at the distance."""
        left = distance - start.distance_to(st.pose)
        if left <= 0.005:
            return Step.ARRIVED
        v = min(speed, math.sqrt(2.0 * base.max_linear_accel * 0.5 * left))
        return -max(v, 0.02), 0.0

    yield from motion_loop(ctx, base, step, fault="base fault while backing off", deadline=t_end,
                           timeout=f"backing off {distance:g} m not done after {timeout:g} s")
    return base.state().pose


def _lidar_room_behind(ctx: SkillContext, base: Base, start: Pose2D, distance: float) -> float:
    """How far [m] (up to ``distance``) the base can back straight off from ``start`` by
    the lidar (the run's local planner fed the newest scan): the footprint keeps the
    costmap's clearance (or gets no closer than now) and stays out of each tracked
    circle's safety radius, and :data:`BACK_OFF_PERSON_GAP` beyond it for people. The
    static-map check alone backed a UR3e 0.3 m into someone standing behind it (UR3e
    lab crowd seed 2904366694: 1 mm from the footprint), and the turn that followed
    swept the arm into them."""
    planner = local_planner(ctx, local_drive_config(ctx, base, None).planner)
    lidar = ctx.robot.lidar
    assert lidar is not None
    scan = lidar.scan()
    if scan is not None:
        planner.observe(scan, start)
    return planner.room_behind(start, distance, ctx.clock.now(), person_gap=BACK_OFF_PERSON_GAP, from_here=True)


def _goal_from_params(ctx: SkillContext, goal: str | None, x: float | None, y: float | None,
                      theta: float | None) -> tuple[Pose2D, str]:
    if goal is not None:
        if x is not None or y is not None or theta is not None:
            raise SkillFailure(FailureKind.PRECONDITION, "navigate: give either 'goal' or x/y/theta, not both")
        return base_pose(ctx, goal), goal
    if x is None or y is None:
        raise SkillFailure(FailureKind.PRECONDITION, "navigate: give 'goal' (a named pose) or 'x' and 'y'")
    base = ctx.robot.base
    assert base is not None
    th = theta if theta is not None else base.state().pose.theta
    return Pose2D(x, y, th), f"({x:.2f}, {y:.2f})"


@skill(
    "navigate",
    params=[
        Param("goal", str, doc="named base pose: 'home', a profile 'places' key or one a skill package adds "
                               "(the fetch package's 'depot')"),
        Param("x", float, unit="m", doc="goal x in map (instead of 'goal')"),
        Param("y", float, unit="m", doc="goal y in map"),
        Param("theta", float, unit="rad", doc="goal heading in map (default: current heading)"),
        Param("max_speed", float, unit="m/s", doc="lower the profile's speed limit"),
        Param("timeout", float, unit="s", doc="fail after this much clock time (default: profile nav.timeout)"),
    ],
    outputs=[Output("pose", list, doc="[x, y, theta] reached, map frame [m, m, rad]")],
    needs=("base",),
)
def navigate(ctx: SkillContext, goal: str | None = None, x: float | None = None, y: float | None = None,
             theta: float | None = None, max_speed: float | None = None, timeout: float | None = None) -> SkillGen:
    """Drive the base to a named pose or x/y/theta: A* on the occupancy map inflated by
    the robot radius, then path tracking (with ``nav.local_planner``: the local planner,
    which re-plans, recovers and backs off from contacts). PLANNING "no path to ..." when
    A* finds none; EXECUTION on a bumper or other base fault, or on timeout;
    PRECONDITION "not localised: ..." while the localiser has not converged (the mission's
    recovery runs ``localize``)."""
    pose, label = _goal_from_params(ctx, goal, x, y, theta)
    limit = timeout if timeout is not None else nav_settings(ctx).timeout
    reached = yield from drive_path(ctx, pose, label, timeout=limit, max_v=max_speed)
    return {"pose": [reached.x, reached.y, reached.theta]}


@skill(
    "back_off",
    params=[
        Param("distance", float, unit="m", required=True, doc="how far to drive straight backwards"),
        Param("speed", float, unit="m/s", default=0.2, doc="top speed"),
        Param("timeout", float, unit="s", default=15.0, doc="fail after this much clock time"),
    ],
    outputs=[Output("pose", list, doc="[x, y, theta] reached, map frame [m, m, rad]")],
    needs=("base",),
)
def back_off(ctx: SkillContext, distance: float, speed: float = 0.2, timeout: float = 15.0) -> SkillGen:
    """Drive straight backwards ``distance`` [m] on odometry (away from a shelf before the
    arm folds), with a map only as far as the line behind stays free in the inflated map
    (``back_off_shortened``). EXECUTION on a base fault or on timeout."""
    if not (math.isfinite(distance) and math.isfinite(speed) and math.isfinite(timeout)) \
            or distance < 0 or speed <= 0 or timeout <= 0:
        raise SkillFailure(FailureKind.PRECONDITION,
                           f"back_off: distance must be >= 0 m and speed, timeout > 0, got {distance:g} m, "
                           f"{speed:g} m/s, {timeout:g} s")
    reached = yield from back_off_by(ctx, distance, speed=speed, timeout=timeout)
    return {"pose": [reached.x, reached.y, reached.theta]}
