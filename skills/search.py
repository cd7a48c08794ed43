"""The ``search`` skill: the seed paper's search phase.

If the requested marker is not in view, the robot turns in place in ``step`` degree
steps (30 by default) clockwise through a full turn, stopping, settling and checking the
camera at each step; if the marker is still not found it drives (A*) to the next search
location of the list and repeats; it stops as soon as the marker is seen. The estimate
(averaged over a few frames) goes to the world model like ``detect_marker``'s.

Settings: the profile's ``search:`` section (:class:`SearchSettings`: the locations, the
turn step, the settle time, the head pans); an arm-mounted camera is first pointed forward
with the ``arm.look`` pose. On a robot with a pan/tilt head, ``head_pans`` (off by default)
looks at each of those pan angles, at the head's home tilt, before the base turns on: a
head turn is cheaper than a base turn (no braking, no odometry drift), so the base can step
by more; the head is back at its home pose when the search ends, however it ends. World model: :class:`SearchProgress` of the latest search under
``search.progress``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator
from dataclasses import dataclass
from typing import Any

from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillContext,
    SkillFailure,
    SkillGen,
    skill,
    wait_goal,
)
from mmexec.skills.manipulation.arm import arm_settings, move_named
from mmexec.skills.navigation.navigate import drive_path, rotate_by
from mmexec.skills.perception.detect import camera_settings, look
from mmexec.skills.poses import base_pose, pose_list
from mmexec.skills.primitives import brake
from mmexec.skills.profile import declare_settings, setting

__all__ = ["WORLD_SEARCH", "SearchProgress", "SearchSettings", "search", "search_settings"]

log = logging.getLogger(__name__)

WORLD_SEARCH = "search.progress"


@dataclass(frozen=True)
class SearchSettings:
    """The ``search:`` section of a robot profile: where to search and how to look."""

    locations: list[tuple[float, float, float]] = setting(
        [], unit="m, m, rad", base_pose=True, doc="base poses [x, y, theta] in map visited in order by search")
    step_deg: float = setting(30.0, unit="deg", ge=1, le=180, doc="turn between two views of a search")
    settle_time: float = setting(0.2, unit="s", ge=0, doc="wait after a turn before looking")
    head_pans: list[float] = setting(
        [], unit="rad", doc="with a pan/tilt head: pans looked at (home tilt) at each base heading; empty: the head stays")


search_settings = declare_settings("search", SearchSettings, package=__name__,
                                   doc="the search skill: locations, turn step, settle time")


@dataclass
class SearchProgress:
    """What the latest search did: views captured, locations visited, where it found the
    marker (map pose [x, y, theta]) or None."""

    marker: int
    views: int = 0
    locations_visited: int = 0
    found_at: tuple[float, float, float] | None = None


def _locations(ctx: SkillContext, given: list[Any] | None) -> list[tuple[Pose2D, str]]:
    raw = given if given else [list(p) for p in search_settings(ctx).locations]
    out = []
    for i, loc in enumerate(raw):
        if isinstance(loc, str):
            out.append((base_pose(ctx, loc), loc))
        else:
            out.append((pose_list(loc, f"search: locations[{i}]"), f"search location {i + 1}"))
    return out


def _head_views(ctx: SkillContext, pans: list[float]) -> list[float | None]:
    """The head pans to look at per base heading: [None] (the head stays) without a head
    or without pans."""
    head = ctx.robot.head
    if head is None or not pans:
        return [None]
    for pan in pans:
        problem = head.limit_problem(pan, head.home[1])
        if problem:
            raise SkillFailure(FailureKind.PRECONDITION, f"search: profile search.head_pans: {problem}")
    return list(pans)


def _point_head(ctx: SkillContext, pan: float, tilt: float, settle: float) -> Generator[None, None, None]:
    head = ctx.robot.head
    assert head is not None
    yield from wait_goal(ctx, head.point(pan, tilt), timeout=10.0)
    end = ctx.clock.now() + settle
    while ctx.clock.now() < end - 1e-9:
        yield


def _settle(ctx: SkillContext, seconds: float) -> Generator[None, None, None]:
    base = ctx.robot.base
    assert base is not None
    rested = yield from brake(ctx, base)
    if not rested:
        raise SkillFailure(FailureKind.EXECUTION, "search: the base did not come to rest")
    end = ctx.clock.now() + seconds
    while ctx.clock.now() < end - 1e-9:
        base.stop()
        yield


@skill(
    "search",
    params=[
        Param("marker", int, required=True, doc="ArUco id to search for"),
        Param("step", float, unit="deg", doc="rotation step, clockwise (default: profile search.step_deg)"),
        Param("turn", float, unit="deg", default=360.0, doc="total rotation at each location"),
        Param("locations", list, doc="search locations after the current one: [x, y, theta] in map or "
                                     "named poses (default, or an empty list: profile search.locations)"),
        Param("max_locations", int, doc="visit at most this many locations from the list"),
        Param("frames", int, doc="frames averaged once found (default: profile camera.detect_frames)"),
        Param("settle", float, unit="s", doc="wait after each step before capturing (default: profile search.settle_time)"),
        Param("timeout", float, unit="s", default=300.0, doc="give up after this much clock time"),
    ],
    outputs=[
        Output("pose", list, doc="[x, y, z, yaw] of the marker in map [m, rad]"),
        Output("views", int, doc="camera views checked"),
    ],
    needs=("base", "camera"),
)
def search(ctx: SkillContext, marker: int, step: float | None = None, turn: float = 360.0,
           locations: list[Any] | None = None, max_locations: int | None = None, frames: int | None = None,
           settle: float | None = None, timeout: float = 300.0) -> SkillGen:
    """Find marker ``marker``: check the camera; turn clockwise in steps through ``turn``
    degrees checking at each step (with ``search.head_pans`` and a head: at each of those
    head pans); then go to the next search location and repeat; a location the planner
    finds no path to is skipped (``search_skipped``). EXECUTION "marker K not found ..."
    when every location was searched or skipped."""
    prof = search_settings(ctx)
    step_deg = prof.step_deg if step is None else step
    if not 1.0 <= step_deg <= 180.0 or not 0.0 <= turn <= 720.0:
        raise SkillFailure(FailureKind.PRECONDITION, f"search: step {step_deg:g} deg must be in 1..180 and turn in 0..720")
    n_frames = camera_settings(ctx).detect_frames if frames is None else frames
    settle_s = prof.settle_time if settle is None else settle
    locs = _locations(ctx, locations)
    if max_locations is not None:
        locs = locs[:max(0, max_locations)]
    progress = SearchProgress(marker)
    ctx.world[WORLD_SEARCH] = progress
    base = ctx.robot.base
    assert base is not None
    deadline = ctx.clock.now() + timeout
    # an arm-mounted camera must look forward first
    look_pose = arm_settings(ctx).look
    if look_pose is not None and ctx.robot.arm is not None:
        yield from move_named(ctx, look_pose)
    n_steps = math.floor(turn / step_deg + 1e-9)
    stops: list[tuple[Pose2D, str] | None] = [None] + list(locs)
    skipped: list[str] = []
    pans = _head_views(ctx, prof.head_pans)
    if pans == [None]:
        return (yield from _search_stops(ctx, marker, stops, skipped, progress, n_steps, step_deg, settle_s,
                                         n_frames, deadline, timeout, pans))
    head = ctx.robot.head
    assert head is not None
    try:
        found = yield from _search_stops(ctx, marker, stops, skipped, progress, n_steps, step_deg, settle_s,
                                         n_frames, deadline, timeout, pans)
    except BaseException:
        head.point(*head.home)  # not waited for: the search failed or was cancelled
        raise
    yield from _point_head(ctx, *head.home, 0.0)
    return found


def _search_stops(ctx: SkillContext, marker: int, stops: list[tuple[Pose2D, str] | None], skipped: list[str],
                  progress: SearchProgress, n_steps: int, step_deg: float, settle_s: float, n_frames: int,
                  deadline: float, timeout: float, pans: list[float | None]) -> SkillGen:
    """The search's stops, turns and views (see :func:`search`)."""
    base = ctx.robot.base
    assert base is not None
    for stop in stops:
        if stop is not None:
            pose, label = stop
            try:
                yield from drive_path(ctx, pose, label, timeout=max(1.0, deadline - ctx.clock.now()), viewpoint=True)
            except SkillFailure as e:
                if e.kind is not FailureKind.PLANNING:
                    raise
                # unreachable from here (an obstacle closes the way): search the next one
                skipped.append(label)
                ctx.emit("search_skipped", location=label, reason=e.reason, node=ctx.node_path)
                continue
            progress.locations_visited += 1
        for k in range(n_steps + 1):
            if k > 0:
                if step_deg * k >= 360.0 - 1e-6:
                    break  # a full turn looks at the first view again
                yield from rotate_by(ctx, -math.radians(step_deg))
            yield from _settle(ctx, settle_s)
            for pan in pans:
                if pan is not None:
                    head = ctx.robot.head
                    assert head is not None
                    yield from _point_head(ctx, pan, head.home[1], settle_s)
                progress.views += 1
                est = yield from look(ctx, marker, n_frames)
                if est is not None:
                    p = base.state().pose
                    progress.found_at = (p.x, p.y, p.theta)
                    ctx.emit("search_found", marker=marker, views=progress.views,
                             locations=progress.locations_visited, pose=[round(v, 4) for v in est.as_list()],
                             node=ctx.node_path)
                    return {"pose": est.as_list(), "views": progress.views}
                if ctx.clock.now() > deadline:
                    raise SkillFailure(FailureKind.EXECUTION,
                                       f"search: marker {marker} not found within {timeout:g} s ({progress.views} views)")
    unreachable = f" ({len(skipped)} unreachable: {', '.join(skipped)})" if skipped else ""
    raise SkillFailure(FailureKind.EXECUTION,
                       f"marker {marker} not found: {progress.views} views at {progress.locations_visited + 1} locations"
                       + unreachable)


