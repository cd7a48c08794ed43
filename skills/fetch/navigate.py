"""Base motion for the fetch mission: grid A* on the robot's occupancy map inflated by
its radius, then pure-pursuit path tracking within velocity and acceleration limits
(:mod:`mmexec.skills.navigation`), and the approach to a stand-off pose facing a marker.

Skills: ``navigate`` (to a named pose or x/y/theta) and ``approach`` (stand-off in front
of a marker). Both emit the seed's base states as ``base_status`` events: ``to_goal``
when a path was found and the base starts moving, ``goal_ok`` on arrival, ``goal_fail``
when there is no path or the motion failed, ``idle`` once the base is at rest again.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator
from typing import Any

from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import Base, Pose2D
from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillCancelled,
    SkillContext,
    SkillFailure,
    skill,
)
from mmexec.skills.fetch.common import (
    WORLD_COSTMAP,
    base_status,
    fetch_profile,
    markers,
    named_base_pose,
)
from mmexec.skills.fetch.detect import look
from mmexec.skills.navigation import (
    CostMap,
    PathTracker,
    TrackerConfig,
    find_standoff,
    inflate,
    plan_path,
    simplify_path,
)
from mmexec.skills.primitives import brake

__all__ = ["approach", "back_off", "costmap", "drive_path", "navigate", "rotate_by"]

log = logging.getLogger(__name__)

Gen = Generator[None, None, dict[str, Any]]


def costmap(ctx: SkillContext) -> CostMap:
    """The robot's occupancy map inflated by the base radius plus the profile's margin,
    cached in the world model until the map or the radius changes."""
    robot = ctx.robot
    if robot.occupancy is None:
        raise SkillFailure(FailureKind.PRECONDITION,
                           "navigation needs a map: this robot has no occupancy grid (robot.map in the config)")
    base = robot.base
    assert base is not None
    margin = fetch_profile(ctx).nav.margin if "fetch" in ctx.profile else 0.03
    key = (id(robot.occupancy), base.radius, margin)
    cached = ctx.world.get(WORLD_COSTMAP)
    if cached is not None and cached[0] == key and cached[1].grid is robot.occupancy:
        return cached[1]
    cm = inflate(robot.occupancy, base.radius, margin)
    ctx.world[WORLD_COSTMAP] = (key, cm)
    return cm


def _tracker_config(ctx: SkillContext, base: Base, max_v: float | None) -> TrackerConfig:
    nav = fetch_profile(ctx).nav if "fetch" in ctx.profile else None
    v = min(max_v or (nav.max_v if nav else 0.5), base.max_linear)
    w = min(nav.max_w if nav else 1.5, base.max_angular)
    return TrackerConfig(
        max_v=v, max_w=w,
        accel_v=min(nav.accel_v if nav else 0.8, base.max_linear_accel),
        accel_w=min(nav.accel_w if nav else 3.0, base.max_angular_accel),
        lookahead=nav.lookahead if nav else 0.35,
        goal_tolerance=nav.goal_tolerance if nav else 0.04,
        heading_tolerance=nav.heading_tolerance if nav else 0.04,
    )


def drive_path(ctx: SkillContext, goal: Pose2D, label: str, *, timeout: float, max_v: float | None = None,
               path: list[tuple[float, float]] | None = None) -> Generator[None, None, Pose2D]:
    """Plan (A*, unless ``path`` is given) from the base's pose to ``goal`` and track the
    path, ending at ``goal.theta``. Emits base states. Failures: PLANNING "no path to
    LABEL"; EXECUTION on a base fault (bumper, cliff, link) or after ``timeout`` clock
    seconds. Cancellation brakes the base before re-raising. Returns the pose reached."""
    base = ctx.robot.base
    if base is None:
        raise SkillFailure(FailureKind.PRECONDITION, "navigation needs a base, and this robot has none")
    cm = costmap(ctx)
    start = base.state().pose
    if path is None:
        search = fetch_profile(ctx).nav.goal_search if "fetch" in ctx.profile else 0.0
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
        path = plan_path(cm, (start.x, start.y), (goal.x, goal.y))
        if path is None:
            base_status(ctx, "goal_fail", goal=[goal.x, goal.y, goal.theta], reason="no path")
            base_status(ctx, "idle")
            raise SkillFailure(FailureKind.PLANNING, f"no path to {label} ({goal.x:.2f}, {goal.y:.2f})")
        path = simplify_path(cm, path)
    # the grid path runs between cell centres: start and end exactly where the base and goal are
    path = [(start.x, start.y)] + list(path[1:-1]) + [(goal.x, goal.y)] if len(path) > 1 else [(goal.x, goal.y)]
    tracker = PathTracker(path, _tracker_config(ctx, base, max_v), goal_heading=goal.theta)
    base_status(ctx, "to_goal", goal=[round(goal.x, 3), round(goal.y, 3), round(goal.theta, 3)], label=label)
    t_end = ctx.clock.now() + timeout
    last = ctx.clock.now()
    try:
        while True:
            st = base.state()
            if st.faults:
                yield from brake(ctx, base)
                base_status(ctx, "goal_fail", reason="base fault: " + ", ".join(sorted(st.faults)))
                raise SkillFailure(FailureKind.EXECUTION,
                                   f"base fault on the way to {label}: {', '.join(sorted(st.faults))}")
            now = ctx.clock.now()
            if now > t_end:
                yield from brake(ctx, base)
                base_status(ctx, "goal_fail", reason="timeout")
                raise SkillFailure(FailureKind.EXECUTION, f"not at {label} after {timeout:g} s")
            dt = now - last
            if dt > 0:
                last = now
                v, w, done = tracker.step(st.pose, st.v, st.w, dt)
                if done:
                    yield from brake(ctx, base)
                    reached = base.state().pose
                    base_status(ctx, "goal_ok", pose=[round(reached.x, 3), round(reached.y, 3), round(reached.theta, 3)])
                    return reached
                base.set_velocity(v, w)
            yield
    except SkillCancelled:
        yield from brake(ctx, base)
        raise
    finally:
        base_status(ctx, "idle")


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
    try:
        while True:
            st = base.state()
            if st.faults:
                yield from brake(ctx, base)
                raise SkillFailure(FailureKind.EXECUTION, f"base fault while turning: {', '.join(sorted(st.faults))}")
            if ctx.clock.now() > t_end:
                yield from brake(ctx, base)
                raise SkillFailure(FailureKind.EXECUTION, f"turn of {math.degrees(angle):.0f} deg not done after {timeout:g} s")
            err = wrap_angle(target - st.pose.theta)
            if abs(err) <= cfg.heading_tolerance:
                yield from brake(ctx, base)
                return base.state().pose
            now = ctx.clock.now()
            dt = max(now - last, 1e-3)
            last = now
            # fastest rate that still stops at the target with the angular acceleration
            w_stop = math.sqrt(2.0 * cfg.accel_w * 0.8 * abs(err))
            w_des = math.copysign(max(min(cfg.max_w, w_stop), 0.1), err)
            step = cfg.accel_w * dt
            w_cmd = max(w_cmd - step, min(w_cmd + step, w_des))
            base.set_velocity(0.0, w_cmd)
            yield
    except SkillCancelled:
        yield from brake(ctx, base)
        raise


def back_off(ctx: SkillContext, distance: float, *, speed: float = 0.2, timeout: float = 15.0) -> Generator[None, None, Pose2D]:
    """Drive straight backwards ``distance`` [m] on odometry, within the acceleration
    limit; brake to rest at the end. With a map, and starting from a free pose, only as
    far as the line behind stays free in the inflated map (the base did not necessarily
    arrive along it: an obstacle beside the stand-off can lie behind it), logged as
    ``back_off_shortened``. EXECUTION failure on a base fault or after ``timeout`` clock
    seconds."""
    base = ctx.robot.base
    assert base is not None
    start = base.state().pose
    if ctx.robot.occupancy is not None and distance > 0:
        cm = costmap(ctx)
        if cm.is_free(start.x, start.y):
            step, free, d = 0.5 * cm.resolution, 0.0, 0.0
            while d < distance:
                d = min(distance, d + step)
                if not cm.is_free(start.x - d * math.cos(start.theta), start.y - d * math.sin(start.theta)):
                    break
                free = d
            if free < distance:
                ctx.emit("back_off_shortened", asked=round(distance, 3), used=round(free, 3), node=ctx.node_path)
                distance = free
    if distance <= 0.005:
        return start
    t_end = ctx.clock.now() + timeout
    try:
        while True:
            st = base.state()
            if st.faults:
                yield from brake(ctx, base)
                raise SkillFailure(FailureKind.EXECUTION, f"base fault while backing off: {', '.join(sorted(st.faults))}")
            if ctx.clock.now() > t_end:
                yield from brake(ctx, base)
                raise SkillFailure(FailureKind.EXECUTION, f"backing off {distance:g} m not done after {timeout:g} s")
            left = distance - start.distance_to(st.pose)
            if left <= 0.005:
                yield from brake(ctx, base)
                return base.state().pose
            v = min(speed, math.sqrt(2.0 * base.max_linear_accel * 0.5 * left))
            base.set_velocity(-max(v, 0.02), 0.0)
            yield
    except SkillCancelled:
        yield from brake(ctx, base)
        raise


def _goal_from_params(ctx: SkillContext, goal: str | None, x: float | None, y: float | None,
                      theta: float | None) -> tuple[Pose2D, str]:
    if goal is not None:
        if x is not None or y is not None or theta is not None:
            raise SkillFailure(FailureKind.PRECONDITION, "navigate: give either 'goal' or x/y/theta, not both")
        return named_base_pose(ctx, goal), goal
    if x is None or y is None:
        raise SkillFailure(FailureKind.PRECONDITION, "navigate: give 'goal' (a named pose) or 'x' and 'y'")
    base = ctx.robot.base
    assert base is not None
    th = theta if theta is not None else base.state().pose.theta
    return Pose2D(x, y, th), f"({x:.2f}, {y:.2f})"


@skill(
    "navigate",
    params=[
        Param("goal", str, doc="named base pose: 'home', 'depot' or a profile 'places' key"),
        Param("x", float, unit="m", doc="goal x in map (instead of 'goal')"),
        Param("y", float, unit="m", doc="goal y in map"),
        Param("theta", float, unit="rad", doc="goal heading in map (default: current heading)"),
        Param("max_speed", float, unit="m/s", doc="lower the profile's speed limit"),
        Param("timeout", float, unit="s", doc="fail after this much clock time (default: profile fetch.nav.timeout)"),
    ],
    outputs=[Output("pose", list, doc="[x, y, theta] reached, map frame [m, m, rad]")],
    needs=("base",),
)
def navigate(ctx: SkillContext, goal: str | None = None, x: float | None = None, y: float | None = None,
             theta: float | None = None, max_speed: float | None = None, timeout: float | None = None) -> Gen:
    """Drive the base to a named pose or x/y/theta: A* on the occupancy map inflated by
    the robot radius, then path tracking. PLANNING "no path to ..." when A* finds none;
    EXECUTION on a bumper or other base fault, or on timeout."""
    pose, label = _goal_from_params(ctx, goal, x, y, theta)
    limit = timeout if timeout is not None else (fetch_profile(ctx).nav.timeout if "fetch" in ctx.profile else 90.0)
    reached = yield from drive_path(ctx, pose, label, timeout=limit, max_v=max_speed)
    return {"pose": [reached.x, reached.y, reached.theta]}


@skill(
    "approach",
    params=[
        Param("marker", int, required=True, doc="marker id whose estimate (world model) to approach"),
        Param("distance", float, unit="m", doc="stand-off from the marker face along its normal"),
        Param("distance_index", int, default=0,
              doc="when 'distance' is not given: index into the profile's approach_distances "
                  "(clamped to the last one); the mission passes the recovery counter"),
        Param("timeout", float, unit="s", doc="fail after this much clock time"),
        Param("refine_from", float, unit="m", default=0.95,
              doc="when the estimate was seen from farther than this, re-estimate it on the way"),
        Param("refine_at", float, unit="m",
              doc="stand-off distance of that intermediate viewpoint (default: profile fetch.refine_at)"),
    ],
    outputs=[
        Output("pose", list, doc="[x, y, theta] reached, map frame"),
        Output("distance", float, doc="stand-off distance used [m]"),
    ],
    needs=("base",),
)
def approach(ctx: SkillContext, marker: int, distance: float | None = None, distance_index: int = 0,
             timeout: float | None = None, refine_from: float = 0.95, refine_at: float | None = None) -> Gen:
    """Reach a stand-off pose at ``distance`` from the marker along its outward normal,
    facing it (small angular offsets around the normal are tried when the straight one
    is blocked). PLANNING failure when no stand-off is free or reachable."""
    est = markers(ctx).get(marker)
    if est is None:
        raise SkillFailure(FailureKind.PRECONDITION, f"approach: no estimate of marker {marker} (search for it first)")
    prof = fetch_profile(ctx)
    if distance is None:
        if distance_index < 0:
            raise SkillFailure(FailureKind.PRECONDITION, f"approach: distance_index must be >= 0, got {distance_index}")
        distance = prof.approach_distances[min(distance_index, len(prof.approach_distances) - 1)]
    if distance <= 0:
        raise SkillFailure(FailureKind.PRECONDITION, f"approach: distance must be > 0 m, got {distance:g}")
    base = ctx.robot.base
    assert base is not None
    cm = costmap(ctx)
    limit = timeout if timeout is not None else prof.nav.timeout
    if refine_at is None:
        refine_at = prof.refine_at
    if est.distance > refine_from and ctx.robot.camera is not None:
        # a marker's orientation seen from afar is poor (degrees of error at 1.5 m): stop
        # at an intermediate stand-off on the way, look again, then aim at the final one
        mid = find_standoff(cm, est.T_map_marker, [refine_at, refine_at + 0.2],
                            angle_offsets=(0.0,), start=(base.state().pose.x, base.state().pose.y))
        if mid.ok and mid.pose is not None:
            yield from drive_path(ctx, mid.pose, f"marker {marker} viewpoint", timeout=limit,
                                  path=simplify_path(cm, mid.path) if mid.path else None)
            better = yield from look(ctx, marker, fetch_profile(ctx).detect_frames)
            if better is not None:
                est = better
    start = base.state().pose
    found = find_standoff(cm, est.T_map_marker, [distance],
                          angle_offsets=(0.0, math.radians(10), -math.radians(10)), start=(start.x, start.y))
    if not found.ok or found.pose is None:
        base_status(ctx, "goal_fail", reason=found.reason or "no stand-off", marker=marker, distance=distance)
        base_status(ctx, "idle")
        why = "no free stand-off" if all(t[2] != "no path from start" for t in found.tried) else "no path"
        raise SkillFailure(FailureKind.PLANNING,
                           f"no path to the stand-off {distance:.2f} m from marker {marker}: {why}")
    ctx.emit("standoff", marker=marker, distance=distance, pose=[round(found.pose.x, 3), round(found.pose.y, 3),
                                                                round(found.pose.theta, 3)], node=ctx.node_path)
    path = simplify_path(cm, found.path) if found.path else None
    reached = yield from drive_path(ctx, found.pose, f"marker {marker} stand-off", timeout=limit, path=path)
    if prof.redetect_at_standoff and ctx.robot.camera is not None:
        # the closest view before the pick: the grasp is planned from this estimate
        near = yield from look(ctx, marker, prof.detect_frames)
        if near is None:
            log.warning("marker %d not in view from its stand-off; the pick uses the estimate from %.2f m",
                        marker, est.distance)
        else:
            ctx.emit("marker_estimate", marker=marker, pose=[round(v, 4) for v in near.as_list()],
                     samples=near.samples, distance=round(near.distance, 3), node=ctx.node_path)
    return {"pose": [reached.x, reached.y, reached.theta], "distance": distance}
