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

**People in the way** (with ``nav.local_planner``: the lidar's tracked people,
:class:`~mmexec.skills.navigation.local_planner.LocalPlanner`): a view whose camera cone
holds a tracked person within :data:`OCCLUSION_RANGE` is not taken as a look at what is
behind them. When the marker is not seen there, the search waits for the cone to clear
(at most :data:`OCCLUSION_WAIT` clock seconds, the base standing, the lidar still
tracking) and looks again. When someone still stands in the view after the wait, within
:data:`SIDESTEP_RANGE` of the camera, the base steps :data:`SIDESTEP` aside, square to
its heading and away from them (the other side when that one has no path; at most
:data:`MAX_SIDESTEPS` per location), looks from there, and once more after a wait if
they are still in the way; the turn goes on from where it stands. A person whose way
runs through the spot the robot looks from walks up to it, waits in front of the camera
and comes back on their way as long as the robot stands there: waiting does not uncover
the shelf behind them, stepping aside does (the LoCoBot lab crowd row's trials 39 and
94). One ``search_occluded`` event per such view (how many people, how long it waited,
whether it cleared, the sidestep). When every location has been searched without
finding the marker and some view was still blocked by people after all that, the search
goes over its locations once more (``search_second_pass``) before it fails: people walk
in front of shelves and go. So it does, over those locations only, when people held the
drive back more than :data:`SHORT_AGAIN` short of a location (the viewpoint drive looks
from up to 0.8 m short): from there the marker can be too small to detect.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

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
from mmexec.skills.navigation.navigate import (
    drive_path,
    rotate_by,
)
from mmexec.skills.navigation.people_watch import PeopleWatch
from mmexec.skills.perception.detect import camera_settings, look
from mmexec.skills.poses import base_pose, pose_list
from mmexec.skills.primitives import brake
from mmexec.skills.profile import declare_settings, setting

__all__ = ["WORLD_SEARCH", "SearchProgress", "SearchSettings", "search", "search_settings"]

log = logging.getLogger(__name__)

WORLD_SEARCH = "search.progress"

#: [m] a tracked person closer than this to the camera, inside its view cone, hides what
#: the view should show (the shelves stand within 2.5 m of the search locations)
OCCLUSION_RANGE = 3.0
#: [s] how long a view waits for the people in its cone to move on before it counts
OCCLUSION_WAIT = 6.0
#: [m] a person still in the view after the wait and this close to the camera is looked
#: past by stepping aside: at 0.5-1 m a person hides a shelf's whole width, and from a
#: step aside the shelf behind them moves out from behind them (parallax)
SIDESTEP_RANGE = 1.5
#: [m] how far the base steps aside, square to its heading (enough for a person of 0.25 m
#: radius 0.6 m ahead to uncover what stands 1.7 m ahead)
SIDESTEP = 0.4
#: sidesteps at most per location visited (each costs a short drive and one more wait)
MAX_SIDESTEPS = 2
#: [s] clock time a sidestep's drive may take
SIDESTEP_TIMEOUT = 20.0
#: [m] a search location the drive stopped farther than this from (with the local
#: planner a viewpoint drive held back by people looks from up to 0.8 m short of it:
#: navigate.VIEW_SHORT) is searched again at the end when the marker was not found: from
#: 0.4 m short of the UR3e's (1.9, 2.5), 2.3 m from the near shelf, a lower-board marker
#: is 7 px wide in the wrist camera's image (the UR3e lab crowd row, seed 269668801)
SHORT_AGAIN = 0.25


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
    occluded: int = 0  #: views with people in the camera cone when first looked at
    hidden: int = 0  #: of those, views still blocked after :data:`OCCLUSION_WAIT`
    #: labels of the locations the drive stopped more than :data:`SHORT_AGAIN` short of
    short: list[str] = field(default_factory=list)


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
    watch = _PeopleWatch.for_robot(ctx)
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
                                         n_frames, deadline, timeout, pans, watch))
    head = ctx.robot.head
    assert head is not None
    try:
        found = yield from _search_stops(ctx, marker, stops, skipped, progress, n_steps, step_deg, settle_s,
                                         n_frames, deadline, timeout, pans, watch)
    except BaseException:
        head.point(*head.home)  # not waited for: the search failed or was cancelled
        raise
    yield from _point_head(ctx, *head.home, 0.0)
    return found


class _PeopleWatch(PeopleWatch):
    """The lidar's tracked people, kept up to date while the search stands and turns,
    and whether they stand in the camera's view (module docstring)."""

    def in_view(self) -> int:
        """How many tracked people stand in the camera's horizontal view cone within
        :data:`OCCLUSION_RANGE` of it now."""
        return len(self.people_in_view())

    def people_in_view(self) -> list[tuple[float, float]]:
        """The tracked people in the camera's horizontal view cone within
        :data:`OCCLUSION_RANGE` of it now: (distance from the camera [m], bearing from
        the optical axis [rad], positive to its left) each, nearest first."""
        cam, base = self.ctx.robot.camera, self.ctx.robot.base
        assert cam is not None and base is not None
        people = self.people()
        if not len(people):
            return []
        T = base.state().pose.matrix() @ cam.pose_in_base()
        cx, cy = T[0, 3], T[1, 3]
        yaw = math.atan2(T[1, 2], T[0, 2])  # the optical axis (z) in map
        k = cam.intrinsics
        half = math.atan2(0.5 * k.width, k.fx)
        d = np.hypot(people.centres[:, 0] - cx, people.centres[:, 1] - cy)
        bearing = np.arctan2(people.centres[:, 1] - cy, people.centres[:, 0] - cx) - yaw
        signed = np.arctan2(np.sin(bearing), np.cos(bearing))
        widen = np.arcsin(np.clip(people.radii / np.maximum(d, 1e-6), 0.0, 1.0))
        inside = (d < OCCLUSION_RANGE) & (np.abs(signed) < half + widen)
        return sorted((float(a), float(b)) for a, b in zip(d[inside], signed[inside]))


def _observed(gen: Generator[None, None, Any], watch: _PeopleWatch | None) -> Generator[None, None, Any]:
    """Run the motion ``gen`` (a turn, a settle) tick by tick, feeding each new lidar scan
    to the tracks between its ticks (people are told from furniture by how they move, so
    the tracks need every scan, not one per view); exceptions thrown in (a cancel) go to
    ``gen``. Returns what ``gen`` returns."""
    if watch is None:
        return (yield from gen)
    try:
        gen.send(None)
        while True:
            try:
                yield
            except GeneratorExit:
                gen.close()
                raise
            except BaseException as e:  # noqa: BLE001 - a cancel (SkillCancelled is one): the motion brakes and re-raises
                gen.throw(e)
            else:
                watch.observe()
                gen.send(None)
    except StopIteration as stop:
        return stop.value


def _wait_for_view(ctx: SkillContext, watch: _PeopleWatch) -> Generator[None, None, bool]:
    """People stand in the view: wait (base stopped, scans tracked) until the cone is
    clear or :data:`OCCLUSION_WAIT` has passed. True when it cleared."""
    base = ctx.robot.base
    assert base is not None
    t0 = ctx.clock.now()
    while ctx.clock.now() - t0 < OCCLUSION_WAIT:
        base.stop()
        yield
        watch.observe()
        if not watch.in_view():
            break
    return not watch.in_view()


def _sidestep(ctx: SkillContext, watch: _PeopleWatch, left: float, deadline: float) -> Generator[None, None, str | None]:
    """Step the base :data:`SIDESTEP` aside, square to its heading, keeping the heading:
    to the side away from a person ``left`` of the optical axis (bearing [rad], positive
    to its left), else the other side when that one has no path. The side taken
    ("left", "right"), or None when neither could be driven (the search goes on from
    where the base stands)."""
    base = ctx.robot.base
    assert base is not None
    p = base.state().pose
    first = -1.0 if left > 0.0 else 1.0  # +1: to the base's left
    for sign in (first, -first):
        goal = Pose2D(p.x - sign * SIDESTEP * math.sin(p.theta), p.y + sign * SIDESTEP * math.cos(p.theta), p.theta)
        try:
            yield from _observed(drive_path(ctx, goal, "search sidestep",
                                            timeout=max(1.0, min(SIDESTEP_TIMEOUT, deadline - ctx.clock.now())),
                                            viewpoint=True), watch)
        except SkillFailure as e:
            if e.kind not in (FailureKind.PLANNING, FailureKind.EXECUTION):
                raise
            log.info("search: no sidestep to the %s (%s)", "left" if sign > 0 else "right", e.reason)
            if e.kind is FailureKind.EXECUTION:
                return None  # stopped on the way (a timeout, people): look from where it stands
            continue
        return "left" if sign > 0 else "right"
    return None


def _look_past_people(ctx: SkillContext, watch: _PeopleWatch, progress: SearchProgress, n_frames: int,
                      settle_s: float, deadline: float, steps: list[int]) -> Generator[None, None, Any]:
    """The view just looked at did not show the marker and people stand in it: wait for
    them, look again when they go; when they stay close, step aside (``steps[0]`` left
    at this location) and look from there, and again after another wait if they are
    still in the way. The estimate, or None. Counts the view as occluded, and as hidden
    when the last look still had people in the way; emits ``search_occluded``."""
    progress.occluded += 1
    t0 = ctx.clock.now()
    people = len(watch.people_in_view())
    est = None
    cleared = yield from _wait_for_view(ctx, watch)
    side = None
    still = [] if cleared else watch.people_in_view()
    if steps[0] > 0 and still and still[0][0] <= SIDESTEP_RANGE:
        steps[0] -= 1
        side = yield from _sidestep(ctx, watch, still[0][1], deadline)
        yield from _observed(_settle(ctx, settle_s), watch)
        est = yield from look(ctx, progress.marker, n_frames)
        watch.observe()
        cleared = not watch.in_view()
        looked = True
        if est is None and not cleared:
            cleared = yield from _wait_for_view(ctx, watch)
            looked = not cleared  # cleared during this wait: look again below
    else:
        looked = not cleared
    progress.hidden += not cleared
    fields: dict[str, Any] = {"sidestep": side} if side is not None else {}
    ctx.emit("search_occluded", marker=progress.marker, view=progress.views, people=people,
             waited=round(ctx.clock.now() - t0, 2), cleared=cleared, **fields, node=ctx.node_path)
    if not looked:  # the view cleared since the last look: look again
        yield from _observed(_settle(ctx, settle_s), watch)
        est = yield from look(ctx, progress.marker, n_frames)
    return est


def _search_stops(ctx: SkillContext, marker: int, stops: list[tuple[Pose2D, str] | None], skipped: list[str],
                  progress: SearchProgress, n_steps: int, step_deg: float, settle_s: float, n_frames: int,
                  deadline: float, timeout: float, pans: list[float | None], watch: _PeopleWatch | None) -> SkillGen:
    """The search's stops, turns and views (see :func:`search`), then, when people stood
    in the way of a view, a second pass over the locations; else, when the drive stopped
    short of some location (:data:`SHORT_AGAIN`), a second pass over those."""
    found = yield from _search_pass(ctx, marker, stops, skipped, progress, n_steps, step_deg, settle_s, n_frames,
                                    deadline, timeout, pans, watch)
    if found is not None:
        return found
    again = [s for s in stops if s is not None]
    if not (watch is not None and progress.hidden):
        # only the locations looked at from short of them (people held the drive back)
        again = [s for s in again if s[1] in progress.short]
    if again and ((watch is not None and progress.hidden) or progress.short):
        ctx.emit("search_second_pass", marker=marker, views=progress.views, occluded=progress.occluded,
                 locations=len(again), short=len(progress.short), node=ctx.node_path)
        log.info("search: marker %d not found (people in %d views, %d locations looked at from short of them): "
                 "searching %d locations again", marker, progress.occluded, len(progress.short), len(again))
        progress.short.clear()
        skipped.clear()
        found = yield from _search_pass(ctx, marker, again, skipped, progress, n_steps, step_deg, settle_s, n_frames,
                                        deadline, timeout, pans, watch)
        if found is not None:
            return found
    unreachable = f" ({len(skipped)} unreachable: {', '.join(skipped)})" if skipped else ""
    people = f"; people in the way of {progress.occluded} views" if progress.occluded else ""
    raise SkillFailure(FailureKind.EXECUTION,
                       f"marker {marker} not found: {progress.views} views at {progress.locations_visited + 1} locations"
                       + unreachable + people)


def _search_pass(ctx: SkillContext, marker: int, stops: list[tuple[Pose2D, str] | None], skipped: list[str],
                 progress: SearchProgress, n_steps: int, step_deg: float, settle_s: float, n_frames: int,
                 deadline: float, timeout: float, pans: list[float | None],
                 watch: _PeopleWatch | None) -> Generator[None, None, dict[str, Any] | None]:
    """One pass over ``stops``: the found outputs, or None."""
    base = ctx.robot.base
    assert base is not None
    for stop in stops:
        steps = [MAX_SIDESTEPS]
        if stop is not None:
            pose, label = stop
            try:
                reached = yield from drive_path(ctx, pose, label, timeout=max(1.0, deadline - ctx.clock.now()),
                                                viewpoint=True)
            except SkillFailure as e:
                if e.kind is not FailureKind.PLANNING:
                    raise
                # unreachable from here (an obstacle closes the way): search the next one
                skipped.append(label)
                ctx.emit("search_skipped", location=label, reason=e.reason, node=ctx.node_path)
                continue
            progress.locations_visited += 1
            if (watch is not None and math.hypot(reached.x - pose.x, reached.y - pose.y) > SHORT_AGAIN
                    and label not in progress.short):
                progress.short.append(label)
        for k in range(n_steps + 1):
            if k > 0:
                if step_deg * k >= 360.0 - 1e-6:
                    break  # a full turn looks at the first view again
                yield from _observed(rotate_by(ctx, -math.radians(step_deg)), watch)
            yield from _observed(_settle(ctx, settle_s), watch)
            for pan in pans:
                if pan is not None:
                    head = ctx.robot.head
                    assert head is not None
                    yield from _point_head(ctx, pan, head.home[1], settle_s)
                progress.views += 1
                est = yield from look(ctx, marker, n_frames)
                if est is None and watch is not None:
                    watch.observe()
                    if watch.in_view():
                        est = yield from _look_past_people(ctx, watch, progress, n_frames, settle_s, deadline, steps)
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
    return None


