"""The button presser's skills (the ROS 2 thesis, section 1.2.3): find the panel's locator
marker with a searching movement of the wrist camera, park in front of the panel, look
at its markers and fit its frame, press the requested buttons along straight lines and
check each one's light with the camera.

Skills: ``find_panel``, ``approach_panel``, ``locate_panel``, ``press_buttons``. Settings:
the profile's ``buttons:`` section (:mod:`mmexec.skills.buttons.profile`), and ``arm``,
``camera``, ``nav``, ``search`` as the general skills read them.

World model: the panel estimate under ``buttons.panel`` (:class:`PanelEstimate`, in
``map``: from the locator until the markers have been fitted), the buttons whose light
this request has seen come on under ``buttons.done``.

Frames: everything is computed in ``map`` and moved into the arm base frame through the
base's odometry pose and the arm mount (:func:`~mmexec.skills.manipulation.arm.T_armbase_map`).
Tool poses of a press are the pressing tip's (the arm's tool frame moved by
``buttons.tool_offset``). Units: m, rad, s.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

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
from mmexec.skills.buttons.lights import LightReading, read_light
from mmexec.skills.buttons.profile import (
    ButtonsSettings,
    buttons_settings,
    layout,
    light_of,
    ordered,
)
from mmexec.skills.manipulation import ArmPlanner, PlanResult
from mmexec.skills.manipulation.arm import (
    GRIPPER_TIMEOUT,
    ArmWorkspace,
    T_armbase_map,
    arm_settings,
    ik_seeds,
    measured_joints,
    move_named,
    off_tick,
    planned,
    with_arm_status,
    workspace,
)
from mmexec.skills.navigation import find_standoff, simplify_path
from mmexec.skills.navigation.navigate import costmap, drive_path, nav_settings, rotate_by
from mmexec.skills.perception import observe_markers
from mmexec.skills.perception.detect import (
    camera_settings,
    detector,
    emit_estimate,
    look,
    next_frame,
)
from mmexec.skills.perception.panel import PanelFit, PanelFitError, fit_panel, press_path
from mmexec.skills.poses import arm_joints, base_pose, pose_list
from mmexec.skills.primitives import brake
from mmexec.skills.search import search_settings

__all__ = ["WORLD_DONE", "WORLD_PANEL", "PanelEstimate", "approach_panel", "find_panel", "locate_panel",
           "press_buttons"]

log = logging.getLogger(__name__)

WORLD_PANEL = "buttons.panel"
WORLD_DONE = "buttons.done"

#: [m] the panel box is put into the planning scene this far behind the fitted face: the
#: caps stand out of it and the pressing tip ends a few mm above the face
SCENE_SETBACK = 0.01
#: [m] the panel box from the locator alone is this much larger on every side in the scene
GUESS_MARGIN = 0.05
#: [clock s] wait after an arm move before a camera frame is used
SETTLE = 0.1


@dataclass
class PanelEstimate:
    """``T_map_panel`` (4x4, map); ``source`` ``locator`` (from the locator marker only,
    the face assumed vertical) or ``fit`` (the markers fitted: ``fit`` holds it)."""

    T_map_panel: np.ndarray
    source: str
    fit: PanelFit | None = None
    seen: dict[int, list[np.ndarray]] = field(default_factory=dict)

    def as_list(self) -> list[float]:
        """[x, y, z, yaw] in map (yaw of the face normal) [m, rad]."""
        T = self.T_map_panel
        return [round(float(T[0, 3]), 4), round(float(T[1, 3]), 4), round(float(T[2, 3]), 4),
                round(math.atan2(float(T[1, 2]), float(T[0, 2])), 4)]


def _level(T: np.ndarray) -> np.ndarray:
    """``T`` with its z (the face normal) made horizontal and its y up (a vertical face)."""
    z = np.array([T[0, 2], T[1, 2], 0.0])
    if np.linalg.norm(z) < 1e-6:
        raise SkillFailure(FailureKind.EXECUTION, "the locator marker faces up or down: not a panel's face")
    z /= np.linalg.norm(z)
    out = np.eye(4)
    out[:3, 1] = (0.0, 0.0, 1.0)
    out[:3, 2] = z
    out[:3, 0] = np.cross(out[:3, 1], z)
    out[:3, 3] = T[:3, 3]
    return out


def _translate(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def panel_estimate(ctx: SkillContext) -> PanelEstimate:
    est = ctx.world.get(WORLD_PANEL)
    if not isinstance(est, PanelEstimate):
        raise SkillFailure(FailureKind.PRECONDITION, "no panel estimate: find the panel first (find_panel)")
    return est


def _settle(ctx: SkillContext, seconds: float) -> Generator[None, None, None]:
    end = ctx.clock.now() + seconds
    while ctx.clock.now() < end - 1e-9:
        yield


def _move_joints(ctx: SkillContext, ws: ArmWorkspace, q1: Sequence[float], what: str) -> Generator[None, None, None]:
    """Plan (against the scene) and execute a joint move."""
    q0 = measured_joints(ctx)
    if max(abs(a - b) for a, b in zip(q0, q1)) < 1e-3:
        return
    boxes, T_am, cfg = ctx.robot.scene, T_armbase_map(ctx), ws.config()

    def job() -> PlanResult:
        ws.scene.set_static_boxes(boxes, T_am)
        return ws.planner.plan(q0, list(q1), cfg)

    res = planned(ctx, (yield from off_tick(ctx, ws, job)), what)
    yield from _follow(ctx, res, what)


def _follow(ctx: SkillContext, res: PlanResult, what: str,
            samples: list[list[float]] | None = None) -> Generator[None, None, None]:
    """Execute a planned trajectory (at most its duration + 5 s); ``samples`` collects the
    measured joints [t, q...] each tick."""
    arm = ctx.robot.arm
    assert arm is not None and res.trajectory is not None
    goal = arm.follow(res.trajectory)
    t0 = ctx.clock.now()
    if samples is not None:
        samples.append([0.0, *measured_joints(ctx)])
    deadline = t0 + res.trajectory.duration + 5.0
    try:
        while not goal.done():
            if ctx.clock.now() > deadline:
                goal.cancel()
                yield from wait_goal(ctx, goal)
                raise SkillFailure(FailureKind.TIMEOUT, f"{what}: took longer than {deadline - t0:.1f} s")
            yield
            if samples is not None:
                samples.append([round(ctx.clock.now() - t0, 3), *measured_joints(ctx)])
        yield from wait_goal(ctx, goal)
    except SkillFailure as e:
        raise SkillFailure(e.kind, f"{what}: {e.reason}") from None


# --------------------------------------------------------------------------- find


@skill(
    "find_panel",
    params=[
        Param("marker", int, doc="the locator marker's id (default: profile buttons.locator)"),
        Param("locations", list, doc="places to search from after the current one: [x, y, theta] or named "
                                     "poses (default, or empty: profile buttons.search_locations, else "
                                     "search.locations)"),
        Param("timeout", float, unit="s", default=300.0, doc="give up after this much clock time"),
    ],
    outputs=[Output("pose", list, doc="[x, y, z, yaw] of the panel's face centre in map, from the locator"),
             Output("views", int, doc="camera views taken")],
    needs=("base", "arm", "camera"),
)
def find_panel(ctx: SkillContext, marker: int | None = None, locations: list[Any] | None = None,
               timeout: float = 300.0) -> SkillGen:
    """The thesis's searching movement: the arm points the wrist camera through
    ``buttons.sweep`` poses, each turned by ``buttons.sweep_pan_deg`` on the first joint;
    when the locator is not seen the base turns ``buttons.turn_deg`` and the arm sweeps
    again, a full turn round; then the base drives to the next search location. The
    panel's pose follows from the locator's (``buttons.locator_position``, the face
    vertical). EXECUTION "locator marker K not found ..." when every place was searched."""
    s = buttons_settings(ctx)
    mid = s.locator if marker is None else marker
    ctx.world.pop(WORLD_PANEL, None)
    ctx.world[WORLD_DONE] = set()
    raw = locations if locations else [list(p) for p in (s.search_locations or search_settings(ctx).locations)]
    stops: list[tuple[Any, str] | None] = [None]
    for i, loc in enumerate(raw):
        stops.append((base_pose(ctx, loc), loc) if isinstance(loc, str)
                     else (pose_list(loc, f"find_panel: locations[{i}]"), f"search location {i + 1}"))
    ws = workspace(ctx)
    n_frames = camera_settings(ctx).detect_frames
    deadline = ctx.clock.now() + timeout
    views = places = 0
    base = ctx.robot.base
    assert base is not None
    # a camera not on the arm (no arm.look pose: the LoCoBot's head) is not swept by the arm
    on_arm = arm_settings(ctx).look is not None
    sweep: list[tuple[str | None, float]] = ([(name, pan) for name in s.sweep for pan in s.sweep_pan_deg] if on_arm
                                             else [(None, 0.0)])
    for stop in stops:
        if stop is not None:
            pose, label = stop
            yield from move_named(ctx, arm_settings(ctx).stow)  # park the arm: the lidar sees past it
            try:
                yield from drive_path(ctx, pose, str(label), timeout=max(1.0, deadline - ctx.clock.now()))
            except SkillFailure as e:
                if e.kind is not FailureKind.PLANNING:
                    raise
                ctx.emit("search_skipped", location=str(label), reason=e.reason, node=ctx.node_path)
                continue
        places += 1
        turned = 0.0
        while True:
            order = sweep if len(sweep) < 2 or views % 2 == 0 else sweep[::-1]  # no needless swing back
            for name, pan in order:
                if name is not None:
                    q = list(arm_joints(ctx.profile, name))
                    q[0] += math.radians(pan)
                    yield from _move_joints(ctx, ws, q, f"search pose {name} {pan:+.0f} deg")
                yield from _settle(ctx, SETTLE)
                views += 1
                est = yield from look(ctx, mid, n_frames)
                if est is not None:
                    emit_estimate(ctx, est)
                    T = _level(est.T_map_marker) @ _translate(-s.locator_position[0], -s.locator_position[1], 0.0)
                    pe = PanelEstimate(T, "locator")
                    ctx.world[WORLD_PANEL] = pe
                    ctx.emit("panel_found", marker=mid, views=views, places=places, distance=round(est.distance, 3),
                             pose=pe.as_list(), node=ctx.node_path)
                    return {"pose": pe.as_list(), "views": views}
                if ctx.clock.now() > deadline:
                    raise SkillFailure(FailureKind.TIMEOUT, f"locator marker {mid} not found within {timeout:g} s "
                                                            f"({views} views)")
            turned += s.turn_deg
            if turned >= 360.0 - 1e-6:
                break
            rested = yield from brake(ctx, base)
            if not rested:
                raise SkillFailure(FailureKind.EXECUTION, "find_panel: the base did not come to rest")
            yield from rotate_by(ctx, math.radians(s.turn_deg))
    raise SkillFailure(FailureKind.EXECUTION, f"locator marker {mid} not found: {views} views at {places} places")


# --------------------------------------------------------------------------- park


@skill(
    "approach_panel",
    params=[
        Param("attempt", int, default=0, doc="0: park at buttons.standoff; 1: retry_shift nearer; 2+: farther"),
        Param("timeout", float, unit="s", doc="fail after this much clock time (default: profile nav.timeout)"),
    ],
    outputs=[Output("pose", list, doc="[x, y, theta] reached, map"), Output("distance", float, doc="stand-off [m]")],
    needs=("base",),
)
def approach_panel(ctx: SkillContext, attempt: int = 0, timeout: float | None = None) -> SkillGen:
    """Park facing the panel at the stand-off distance along its normal (the fitted
    frame when the markers have been fitted, else the locator's), 10 degrees either side
    when straight in front is blocked (then 20). PLANNING when no stand-off is free or reachable."""
    s = buttons_settings(ctx)
    est = panel_estimate(ctx)
    shifts = (0.0, -s.retry_shift, s.retry_shift)
    d = s.standoff + shifts[min(max(attempt, 0), len(shifts) - 1)]
    base = ctx.robot.base
    assert base is not None
    cm = costmap(ctx)
    here = base.state().pose
    found = find_standoff(cm, est.T_map_panel, [d], angle_offsets=tuple(math.radians(a) for a in (0, 10, -10, 20, -20)),
                          start=(here.x, here.y))
    if not found.ok or found.pose is None:
        why = ("no path from here for the footprint" if any(t[2] == "no path from start" for t in found.tried)
               else "no free stand-off")
        raise SkillFailure(FailureKind.PLANNING, f"no path to the panel's stand-off {d:.2f} m: {why}")
    ctx.emit("standoff", marker=s.locator, distance=d, pose=[round(found.pose.x, 3), round(found.pose.y, 3),
                                                             round(found.pose.theta, 3)], node=ctx.node_path)
    limit = timeout if timeout is not None else nav_settings(ctx).timeout
    reached = yield from drive_path(ctx, found.pose, "panel stand-off", timeout=limit,
                                    path=simplify_path(cm, found.path) if found.path else None)
    return {"pose": [reached.x, reached.y, reached.theta], "distance": d}


# --------------------------------------------------------------------------- look and fit


def _tool_camera(ctx: SkillContext, ws: ArmWorkspace) -> np.ndarray:
    """``T_tool_camera``: the arm-mounted camera's optical frame in the arm's tool frame."""
    cam = ctx.robot.camera
    arm = ctx.robot.arm
    assert cam is not None and arm is not None
    T_base_tool = np.asarray(arm.mount, dtype=float) @ ws.kin.fk(measured_joints(ctx))
    return np.linalg.inv(T_base_tool) @ np.asarray(cam.pose_in_base(), dtype=float)


def _view_pose(T_map_panel: np.ndarray, view: Sequence[float]) -> np.ndarray:
    """Camera optical pose in map for ``view`` [dx, dy, distance, roll_deg]: looking into
    the face at the aimed point, image down = the panel's down turned by roll."""
    dx, dy, dist, roll = view
    r = math.radians(roll)
    c, s = math.cos(r), math.sin(r)
    # columns: optical x, y, z in the panel frame (roll 0: x = x_p, y = -y_p, z = -z_p)
    R = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = (dx, dy, dist)
    return T_map_panel @ T


def _panel_in_scene(ws: ArmWorkspace, s: ButtonsSettings, T_am: np.ndarray, T_map_panel: np.ndarray,
                    grow: float) -> None:
    """(worker thread) The panel box, ``grow`` [m] larger on every side, as the planning
    scene's only item, its face ``SCENE_SETBACK`` behind the estimated face."""
    w, h, d = s.body
    box = T_map_panel @ _translate(0.0, 0.0, -d / 2 - SCENE_SETBACK)
    for old in list(ws.scene.items):
        ws.scene.remove_item(old)
    ws.scene.add_item("panel", (w + 2 * grow, h + 2 * grow, d + 2 * grow), T_am @ box)


def _nearest_turns(q: np.ndarray, near: Sequence[float], limits: Sequence[Any]) -> list[float]:
    """``q`` with each joint moved by whole turns (within its limits) as close as it gets
    to ``near``: the same pose, without a needless swing of a joint that turns +-2 pi."""
    out = []
    for v, n, lim in zip(q, near, limits):
        k = round((n - v) / (2 * math.pi))
        for cand in (v + 2 * math.pi * k, v):
            if lim.lower - 1e-9 <= cand <= lim.upper + 1e-9:
                out.append(float(cand))
                break
    return out


def _head_at(ctx: SkillContext, point_map: np.ndarray) -> Generator[None, None, None]:
    """Point a head's camera at ``point_map`` [m, map] (nothing without a head)."""
    head = getattr(ctx.robot, "head", None)
    base = ctx.robot.base
    if head is None:
        return
    T_map_base = base.state().pose.matrix() if base is not None else np.eye(4)
    p = np.linalg.inv(T_map_base) @ np.append(np.asarray(point_map, dtype=float), 1.0)
    yield from wait_goal(ctx, head.look_at(tuple(float(v) for v in p[:3])), timeout=10.0)


def _head_home(ctx: SkillContext) -> Generator[None, None, None]:
    """The head back to its home pose (nothing without a head)."""
    head = getattr(ctx.robot, "head", None)
    if head is not None:
        yield from wait_goal(ctx, head.point(*head.home), timeout=10.0)


def _plan_pose(ctx: SkillContext, ws: ArmWorkspace, planner: ArmPlanner, T_map_tool: np.ndarray, what: str,
               panel: tuple[np.ndarray, float]) -> Generator[None, None, PlanResult]:
    """Plan to a tool pose in map, the panel (``(T_map_panel, grow)``) in the scene."""
    s = buttons_settings(ctx)
    T_am = T_armbase_map(ctx)
    T = T_am @ T_map_tool
    q, seeds, boxes, cfg = measured_joints(ctx), ik_seeds(ctx, ws, T), ctx.robot.scene, ws.config()

    def job() -> PlanResult:
        ws.scene.set_static_boxes(boxes, T_am)
        _panel_in_scene(ws, s, T_am, *panel)
        goal = None
        for k, seed in enumerate([*seeds, q]):
            goal = planner.kin.ik(T, seed, attempts=1 if k < len(seeds) else 40, is_valid=ws.scene.is_valid)
            if goal is not None or planner.stop.is_set():
                break
        if goal is None:
            return planner.plan_to_pose(q, T, ik_seeds=seeds, ik_attempts=40, config=cfg)  # says why
        return planner.plan(q, _nearest_turns(goal, q, planner.kin.limits), cfg)

    return planned(ctx, (yield from off_tick(ctx, ws, job)), what)


@skill(
    "locate_panel",
    params=[Param("frames", int, doc="frames per view (default: profile camera.detect_frames)")],
    outputs=[Output("pose", list, doc="[x, y, z, yaw] of the fitted face centre in map"),
             Output("markers", list, doc="marker ids the fit used"),
             Output("rms", float, doc="fit residual [m]")],
    needs=("arm", "gripper", "camera"),
)
def locate_panel(ctx: SkillContext, frames: int | None = None) -> SkillGen:
    """Close the gripper (its closed fingertips press), point the wrist camera at the
    panel from each of ``buttons.views`` in turn until ``buttons.min_markers`` of its
    markers are seen, then fit the panel's frame to every marker seen (a rigid fit robust
    to one wrong marker, :func:`~mmexec.skills.perception.panel.fit_panel`). EXECUTION when
    fewer than three markers are seen or they do not fit the layout."""
    return (yield from with_arm_status(ctx, _locate(ctx, frames), "locate the panel"))


def _locate(ctx: SkillContext, frames: int | None) -> SkillGen:
    s = buttons_settings(ctx)
    est = panel_estimate(ctx)
    ws = workspace(ctx)
    g = ctx.robot.gripper
    cam = ctx.robot.camera
    assert g is not None and cam is not None
    closing = g.close(force=arm_settings(ctx).grasp_force)
    n = camera_settings(ctx).detect_frames if frames is None else frames
    lay = layout(s)
    seen: dict[int, list[np.ndarray]] = {}
    on_arm = arm_settings(ctx).look is not None
    T_tool_cam = _tool_camera(ctx, ws)
    guess = est.T_map_panel
    det = detector(ctx)
    yield from wait_goal(ctx, closing, timeout=GRIPPER_TIMEOUT)
    # an arm-mounted camera is pointed at the panel from each view in turn; any other
    # camera looks from where it is, a head turned to the panel's centre first
    if not on_arm:
        yield from _head_at(ctx, guess[:3, 3])
    for k, view in enumerate(s.views if on_arm else [None]):
        if view is not None:
            T_tool = _view_pose(guess, view) @ np.linalg.inv(T_tool_cam)
            try:
                res = yield from _plan_pose(ctx, ws, ws.planner, T_tool, f"panel view {k + 1}", (guess, GUESS_MARGIN))
            except SkillFailure as e:
                log.info("panel view %d: %s", k + 1, e.reason)
                continue
            yield from _follow(ctx, res, f"panel view {k + 1}")
        yield from _settle(ctx, SETTLE)
        got = 0
        while got < n:
            frame = yield from next_frame(ctx, cam)
            got += 1
            for ob in observe_markers(frame, det):
                if ob.id in lay.markers:
                    seen.setdefault(ob.id, []).append(np.asarray(ob.T_map_marker, dtype=float)[:3, 3])
            if got < n:
                yield
        if len(seen) >= s.min_markers:
            break
    centres = {i: np.median(np.array(v), axis=0) for i, v in seen.items()}
    try:
        fit = fit_panel(lay, centres, s.fit_config())
    except PanelFitError as e:
        raise SkillFailure(FailureKind.EXECUTION, f"{e} (seen: {sorted(seen) or 'none'})") from None
    pe = PanelEstimate(fit.T_frame_panel, "fit", fit, seen)
    ctx.world[WORLD_PANEL] = pe
    ctx.emit("panel_fit", markers=list(fit.inliers), rejected=list(fit.rejected), rms_mm=round(fit.rms * 1e3, 2),
             pose=pe.as_list(), node=ctx.node_path)
    return {"pose": pe.as_list(), "markers": list(fit.inliers), "rms": fit.rms}


# --------------------------------------------------------------------------- press


def _about_axis(axis: int, angle: float) -> np.ndarray:
    c, s_ = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(4)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s_, s_, c
    return R


def _roll_to_light(T_tool: np.ndarray, axis: int, T_tool_cam: np.ndarray, to_light: np.ndarray) -> float:
    """The turn [rad] about the tool's approach ``axis`` that puts the camera on the side
    of the button its light is on (``to_light``: unit direction in the frame of ``T_tool``)."""
    c = T_tool_cam[:3, 3].copy()
    c[axis] = 0.0
    want = T_tool[:3, :3].T @ to_light
    want[axis] = 0.0
    if np.linalg.norm(c) < 1e-6 or np.linalg.norm(want) < 1e-6:
        return 0.0
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    return math.atan2(want[j], want[i]) - math.atan2(c[j], c[i])


def _light(ctx: SkillContext, centre: np.ndarray, radius: float, contrast: float) -> Generator[None, None, LightReading]:
    cam = ctx.robot.camera
    assert cam is not None
    yield from _settle(ctx, SETTLE)
    frame = yield from next_frame(ctx, cam)
    return read_light(frame, centre, radius, contrast)


@skill(
    "press_buttons",
    params=[Param("buttons", list, doc="button names in the order to press them (default, or empty: all, "
                                       "left to right)")],
    outputs=[Output("outcomes", dict, doc="button -> pressed | pressed (light was already on) | not lit | skipped"),
             Output("pressed", list, doc="the buttons whose light came on"),
             Output("trajectories", str, doc="straight-line trajectories executed / planned (the thesis's measure)")],
    needs=("arm", "camera"),
)
def press_buttons(ctx: SkillContext, buttons: list[Any] | None = None) -> SkillGen:
    """For each requested button (on the fitted panel): plan to the pose above it (facing
    the face orthogonally at ``buttons.press_standoff``, the camera turned to its light),
    read the light, press along the straight line to ``travel + overtravel`` below the
    cap (IK per waypoint, no joint jumps), come back along the same line reversed, read
    the light again. A button lit by an earlier attempt of this request is not pressed
    again. POSTCONDITION naming the buttons whose light stayed off."""
    head_home = arm_settings(ctx).look is None  # a head turned to the panel goes home after
    try:
        out = yield from with_arm_status(ctx, _press(ctx, buttons), "press buttons")
    except SkillFailure:
        if head_home:
            yield from _head_home(ctx)
        raise
    if head_home:
        yield from _head_home(ctx)
    return out


def _press(ctx: SkillContext, buttons: list[Any] | None) -> SkillGen:
    s = buttons_settings(ctx)
    try:
        names = ordered(s, [str(b) for b in buttons] if buttons else None)
    except ValueError as e:
        raise SkillFailure(FailureKind.PRECONDITION, str(e)) from None
    est = panel_estimate(ctx)
    if est.source != "fit":
        raise SkillFailure(FailureKind.PRECONDITION, "the panel has not been fitted to its markers (locate_panel)")
    done: set[str] = ctx.world.setdefault(WORLD_DONE, set())
    ws = workspace(ctx)
    tip = _translate(*s.tool_offset)
    kin = ws.kin.with_tool_offset(tip, name=f"{ws.kin.name}+press tip")
    planner = ArmPlanner(ws.scene, kin, ws.planner.config)
    planner.stop = ws.planner.stop  # off_tick's cancel stops this planner too
    T_tool_cam = np.linalg.inv(tip) @ _tool_camera(ctx, ws)
    on_arm = arm_settings(ctx).look is not None  # the camera rides on the arm: turn it to each light
    lay = layout(s)
    T_mp = est.T_map_panel
    outcomes: dict[str, str] = {}
    planned_n = executed_n = 0
    cfg = ws.config()
    for name in names:
        if name in done:
            outcomes[name] = "pressed"
            continue
        b = lay.button(name)
        spec = light_of(s, name)
        T_mb = T_mp @ _translate(*b.position)
        path = press_path(T_mb, kin.approach_axis, travel=b.travel, name=name, config=s.press_config())
        light_c = (T_mp @ np.array([spec.light[0], spec.light[1], 0.002, 1.0]))[:3]
        to_light = light_c - T_mb[:3, 3]
        to_light /= max(np.linalg.norm(to_light), 1e-9)
        roll = _roll_to_light(path.above, kin.approach_axis, T_tool_cam, to_light) if on_arm else 0.0
        R = _about_axis(kin.approach_axis, roll)
        above, pressed = path.above @ R, path.pressed @ R
        T_am = T_armbase_map(ctx)
        try:
            res = yield from _plan_pose(ctx, ws, planner, above, f"above {name}", (T_mp, 0.0))
        except SkillFailure as e:
            if e.kind is not FailureKind.PLANNING or arm_settings(ctx).look is None:
                raise
            # from a camera view the wrist can be folded where no way leads to the button:
            # start again from the look pose
            log.info("%s; from the look pose", e.reason)
            yield from move_named(ctx, arm_settings(ctx).look)
            res = yield from _plan_pose(ctx, ws, planner, above, f"above {name}", (T_mp, 0.0))
        yield from _follow(ctx, res, f"above {name}")
        before = yield from _light(ctx, light_c, spec.light_diameter / 2 * 0.7, s.light_contrast)
        lines: dict[str, Any] = {}
        for phase, start_T, goal_T in (("press", above, pressed), ("release", pressed, above)):
            q0 = measured_joints(ctx)

            def plan_line(q0: list[float] = q0, goal_T: np.ndarray = goal_T, T_am: np.ndarray = T_am) -> PlanResult:
                return planner.cartesian_path(q0, T_am @ goal_T, step=s.step, max_joint_step=s.max_joint_step,
                                              config=cfg)

            planned_n += 1
            line = planned(ctx, (yield from off_tick(ctx, ws, plan_line)), f"{phase} {name}")
            samples: list[list[float]] = []
            yield from _follow(ctx, line, f"{phase} {name}", samples)
            executed_n += 1
            lines[phase] = _trajectory_record(kin, T_am, T_mb, line, samples)
        after = yield from _light(ctx, light_c, spec.light_diameter / 2 * 0.7, s.light_contrast)
        if after.on:
            done.add(name)
            outcomes[name] = "pressed (light was already on)" if before.on else "pressed"
        else:
            outcomes[name] = "not lit" if after.on is not None else "light not in view"
        ctx.emit("button_press", button=name, outcome=outcomes[name], light_before=before.on, light_after=after.on,
                 excess_after=round(after.excess, 1), node=ctx.node_path)
        ctx.emit("press_trajectory", button=name, **lines, node=ctx.node_path)
    failed = [n for n in names if n not in done]
    result = {"outcomes": outcomes, "pressed": [n for n in names if n in done],
              "trajectories": f"{executed_n}/{planned_n}"}
    ctx.emit("buttons_result", **result, node=ctx.node_path)
    if failed:
        raise SkillFailure(FailureKind.POSTCONDITION, "light off after pressing "
                           + ", ".join(f"{n} ({outcomes.get(n, 'not pressed')})" for n in failed))
    return result


def _trajectory_record(kin: Any, T_am: np.ndarray, T_map_button: np.ndarray, line: PlanResult,
                       samples: list[list[float]]) -> dict[str, Any]:
    """Planned and executed tip positions of one straight line, in the button's frame
    (mm; z along the face normal, 0 at the cap's rest position): ``planned`` [[t, x, y,
    z]] from the timed trajectory's samples, ``executed`` [[t, x, y, z]] from the joints
    measured each tick."""
    T_button_armbase = np.linalg.inv(T_map_button) @ np.linalg.inv(T_am)
    traj = line.trajectory
    assert traj is not None

    def tip(q: Sequence[float]) -> list[float]:
        p = T_button_armbase @ kin.fk(q)[:, 3]
        return [round(float(v) * 1e3, 2) for v in p[:3]]

    planned_pts = [[round(float(t), 3), *tip(q)] for t, q in zip(traj.times, traj.positions)]
    executed = [[s[0], *tip(s[1:])] for s in samples]
    return {"planned": planned_pts, "executed": executed}
