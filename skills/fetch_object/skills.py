"""The fetch_object mission's skills: find an untagged object by name, drive up to it, look
again, let the operator correct a dangerous item's grasp, pick it (docs/fetch_object.md).

* ``find_object``: the catalogue's likely places first, then the general search locations
  (:func:`~mmexec.skills.catalogue.search_order`); at each, at the profile's base
  headings, a ``scan`` (the head's or the wrist's camera positions, two predictions
  each, fused in map); the target goes to the world model.
* ``approach_object``: a stand-off facing the object from its support's free side (the
  marker normal's counterpart: the direction from the object to the nearest free cell of
  the map, i.e. perpendicular to the support's nearest edge), at the grasp mode's
  distances.
* ``locate_object``: the closest view, from the stand-off: the grasp point the pick uses.
* ``mark_dangerous``: for an item the catalogue flags, ``ask_operator`` (point) on the
  last frame with the box and the predicted grasp pixel; the grasp pixel moves to the
  mean of the predicted and clicked pixels (paper Fig. 7), logged with both; no answer
  within the timeout fails (TIMEOUT).
* ``pick_object``: a top grasp (pre-grasp above, orthogonal to the support) or a front
  grasp (horizontal, from the robot's side) at the estimated centre of mass, planned and
  executed like the fetch mission's pick.

World model: :data:`WORLD_TARGET` (:class:`ObjectTarget`), :data:`WORLD_DETECTOR`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator
from dataclasses import dataclass, replace

import numpy as np

from mmexec.config.yamlload import InputError
from mmexec.drivers.geometry import planar_transform
from mmexec.drivers.interfaces import CameraFrame, Pose2D
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
from mmexec.skills.catalogue import (
    Catalogue,
    CatalogueItem,
    UnknownItem,
    load_catalogue,
    search_order,
)
from mmexec.skills.fetch_object.detector import make_detector
from mmexec.skills.fetch_object.profile import (
    FetchObjectSettings,
    GraspSettings,
    fetch_object_settings,
    resolve_path,
)
from mmexec.skills.manipulation import CANCELLED, PlanResult, grasp_poses
from mmexec.skills.manipulation.arm import (
    GRIPPER_TIMEOUT,
    WORLD_ARM,
    WORLD_HELD,
    ArmWorkspace,
    T_armbase_map,
    arm_settings,
    execute,
    holding,
    ik_seeds,
    measured_joints,
    move_named,
    off_tick,
    planned,
    planner_params,
    release,
    with_arm_status,
    workspace,
)
from mmexec.skills.manipulation.holistic import back_off_distance
from mmexec.skills.manipulation.holistic_skill import holistic_seed
from mmexec.skills.navigation import find_standoff, simplify_path
from mmexec.skills.navigation.navigate import (
    back_off,
    base_status,
    costmap,
    drive_path,
    nav_settings,
    rotate_by,
)
from mmexec.skills.operator import ask_operator
from mmexec.skills.perception.detect import next_frame
from mmexec.skills.perception.detector import Detection, ObjectDetector
from mmexec.skills.perception.grasp_point import (
    GraspPoint,
    GraspPointError,
    correct_grasp_pixel,
    estimate_grasp,
    move_grasp,
)
from mmexec.skills.perception.scan import WORLD_OBJECT_DETECTOR, WORLD_SCAN, ScanResult, scan
from mmexec.skills.primitives import brake
from mmexec.skills.search import search_settings

__all__ = ["WORLD_CATALOGUE", "WORLD_DETECTOR", "WORLD_GRASP_FRAME", "WORLD_TARGET", "ObjectTarget", "catalogue", "detector"]

log = logging.getLogger(__name__)

WORLD_TARGET = "fetch_object.target"
WORLD_DETECTOR = "fetch_object.detector"
WORLD_CATALOGUE = "fetch_object.catalogue"
#: the current target's grasp frame (4x4, map): what pick_object and holistic_standoff plan to
WORLD_GRASP_FRAME = "fetch_object.grasp_frame"
#: clock seconds a camera may give no frame before a look fails
FRAME_TIMEOUT = 2.0
#: [m] a closer look that moves the object's centre farther than this from the estimate
#: it was found with, from a more oblique view, is not trusted (:func:`_more_oblique`)
RELOCATE_TOLERANCE = 0.04
#: [m] per side: the held object is modelled this much smaller (it rests on its support)
HELD_CLEARANCE = 0.005


@dataclass(frozen=True)
class ObjectTarget:
    """The requested object as last seen: ``item`` (catalogue entry), ``detection`` (class,
    confidence, box of the best view), ``grasp`` (:class:`GraspPoint` in map, from that
    view), ``frame`` (that view's camera frame), ``centre`` (3,) [m] fused over the
    predictions, ``distance`` [m] from the camera, ``predictions`` fused, ``normal``: the
    support's outward normal (map x, y) found when the object was first seen (the
    stand-off and a front grasp come along it)."""

    item: CatalogueItem
    detection: Detection
    grasp: GraspPoint
    frame: CameraFrame
    centre: np.ndarray
    distance: float
    predictions: int
    normal: tuple[float, float] | None = None


# --------------------------------------------------------------------------- world model


def catalogue(ctx: SkillContext) -> Catalogue:
    """The profile's catalogue (loaded once per run and checked against the named poses
    and the detector's classes); PRECONDITION naming the file on a problem."""
    cat = ctx.world.get(WORLD_CATALOGUE)
    if isinstance(cat, Catalogue):
        return cat
    prof = fetch_object_settings(ctx)
    if not prof.catalogue:
        raise SkillFailure(FailureKind.PRECONDITION, "profile.fetch_object.catalogue: no catalogue file given")
    places = set((ctx.profile.get("places") or {}).keys()) | {"home", "depot"}
    try:
        cat = load_catalogue(resolve_path(prof.catalogue), places=places, classes=detector(ctx).classes)
    except (InputError, OSError) as e:
        raise SkillFailure(FailureKind.PRECONDITION, f"catalogue: {e}") from None
    ctx.world[WORLD_CATALOGUE] = cat
    return cat


def detector(ctx: SkillContext) -> ObjectDetector:
    """The profile's object detector (built once per run)."""
    det = ctx.world.get(WORLD_DETECTOR)
    if det is not None:
        return det  # type: ignore[no-any-return]
    d = fetch_object_settings(ctx).detector
    try:
        det = make_detector(d.backend, model=str(resolve_path(d.model)) if d.model else "", classes=tuple(d.classes),
                            layout=d.layout, input_size=tuple(d.input_size) if d.input_size else None)  # type: ignore[arg-type]
    except ValueError as e:  # ModelError: "FILE: message"
        raise SkillFailure(FailureKind.PRECONDITION, f"profile.fetch_object.detector: {e}") from None
    ctx.world[WORLD_DETECTOR] = det
    return det


def _item(ctx: SkillContext, name: str) -> CatalogueItem:
    try:
        return catalogue(ctx).item(name)
    except UnknownItem as e:
        raise SkillFailure(FailureKind.PRECONDITION, str(e)) from None


def _target(ctx: SkillContext, who: str) -> ObjectTarget:
    t = ctx.world.get(WORLD_TARGET)
    if not isinstance(t, ObjectTarget):
        raise SkillFailure(FailureKind.PRECONDITION, f"{who}: no object found yet (run find_object first)")
    return t


def _grasp_mode(prof: FetchObjectSettings, item: CatalogueItem) -> tuple[str, GraspSettings]:
    mode = item.grasp or prof.grasp
    return mode, (prof.top if mode == "top" else prof.front)


# --------------------------------------------------------------------------- looking


def _settle(ctx: SkillContext, seconds: float) -> Generator[None, None, None]:
    base = ctx.robot.base
    if base is not None:
        yield from brake(ctx, base)
    end = ctx.clock.now() + seconds
    while ctx.clock.now() < end - 1e-9:
        if base is not None:
            base.stop()
        yield


def look_for(ctx: SkillContext, item: CatalogueItem, frames: int) -> Generator[None, None, ObjectTarget | None]:
    """Up to ``frames`` predictions (one camera frame per tick) of ``item``'s class, fused:
    the best detection's box and grasp point, the centre averaged over the predictions
    whose grasp point could be estimated. None when the first frame shows no such object."""
    cam = ctx.robot.camera
    if cam is None:
        raise SkillFailure(FailureKind.PRECONDITION, "fetch_object needs a camera, and this robot has none")
    det = detector(ctx)
    min_conf = fetch_object_settings(ctx).detector.min_confidence
    best: tuple[Detection, GraspPoint, CameraFrame] | None = None
    centres: list[np.ndarray] = []
    got = 0
    while got < frames:
        frame = yield from next_frame(ctx, cam, FRAME_TIMEOUT)
        got += 1
        hits = [d for d in det.detect(frame.rgb) if d.label == item.detector_class and d.confidence >= min_conf]
        for d in hits:
            try:
                g = estimate_grasp(frame, d.box, size=item.size)
            except GraspPointError as e:
                log.info("%s: no grasp point from %s: %s", item.name, d.box, e)
                continue
            centres.append(g.centre)
            if best is None or d.confidence > best[0].confidence:
                best = (d, g, frame)
            break  # the most confident object of the class in this frame
        if best is None:
            return None
        if got < frames:
            yield
    assert best is not None
    d, g, frame = best
    cam_xy = (frame.T_map_base @ frame.T_base_camera)[:3, 3]
    centre = np.mean(centres, axis=0)
    return ObjectTarget(item, d, g, frame, centre, float(np.linalg.norm(g.centre - cam_xy)), len(centres))


def scan_for(ctx: SkillContext, item: CatalogueItem) -> Generator[None, None, ObjectTarget | None]:
    """The ``scan`` skill (skills/perception/scan.py) where the robot stands, with this
    mission's detector: the profile's ``scan`` camera positions (head poses, or wrist
    poses; one view without either), ``scan.predictions`` each, fused in map. The target:
    the most confident object of the item's class, its grasp point from the box and
    depth of its most confident prediction, its centre the fused mean. None when the
    scan saw none."""
    ctx.world[WORLD_OBJECT_DETECTOR] = detector(ctx)
    try:
        yield from scan(ctx, label=item.detector_class, size=list(item.size))
    except SkillFailure as e:
        if e.kind is not FailureKind.EXECUTION or not e.reason.startswith("scan: no "):
            raise  # a camera or head fault, not an empty view
        return None
    res = ctx.world.get(WORLD_SCAN)
    obj = res.best(item.detector_class) if isinstance(res, ScanResult) else None
    if obj is None:
        return None
    best = obj.best
    try:
        g = estimate_grasp(best.frame, best.box, size=item.size)
    except GraspPointError as e:
        log.info("%s: no grasp point from the scan's best box %s: %s", item.name, best.box, e)
        return None
    cam = (best.frame.T_map_base @ best.frame.T_base_camera)[:3, 3]
    return ObjectTarget(item, Detection(obj.label, obj.confidence, best.box), g, best.frame, obj.position,
                        float(np.linalg.norm(g.centre - cam)), obj.seen)


def _record(ctx: SkillContext, t: ObjectTarget, where: str) -> None:
    """Put the target in the world model with its support normal (kept from an earlier
    sighting of the same request: the support does not change when the robot moves) and
    its grasp frame (:data:`WORLD_GRASP_FRAME`, the frame the holistic planner plans to)."""
    old = ctx.world.get(WORLD_TARGET)
    if isinstance(old, ObjectTarget) and old.item.name == t.item.name and old.normal is not None:
        t = replace(t, normal=old.normal)
    else:
        cam = (t.frame.T_map_base @ t.frame.T_base_camera)[:3, 3]
        t = replace(t, normal=support_normal(ctx, t.grasp.centre[:2], cam[:2]))
    ctx.world[WORLD_TARGET] = t
    ctx.world[WORLD_GRASP_FRAME] = _grasp_frame(t, _grasp_mode(fetch_object_settings(ctx), t.item)[0])
    ctx.emit("object_estimate", item=t.item.name, label=t.detection.label, confidence=round(t.detection.confidence, 3),
             box=list(t.detection.box), centre=[round(float(v), 4) for v in t.centre], grasp_pixel=list(t.grasp.pixel),
             yaw=round(t.grasp.yaw, 3), distance=round(t.distance, 3), predictions=t.predictions, where=where,
             node=ctx.node_path)


@skill(
    "find_object",
    params=[
        Param("item", str, required=True, doc="the item's name in the catalogue"),
        Param("timeout", float, unit="s", default=400.0, doc="give up after this much clock time"),
    ],
    outputs=[Output("centre", list, doc="[x, y, z] of the object's centre of mass in map [m]"),
             Output("place", str, doc="where it was found (a place name or search_locations[i])"),
             Output("grasp", str, doc="the item's grasp: top or front (catalogue, else the profile's)"),
             Output("size", list, doc="the item's size [m] (catalogue)"),
             Output("back_off", float, doc=(
                 "how far [m] pick_object backs off before its carry posture (profile fetch_object.back_off)"))],
    needs=("base", "camera"),
)
def find_object(ctx: SkillContext, item: str, timeout: float = 400.0) -> SkillGen:
    """Visit the item's likely places, then the general search locations; at each, look at
    the profile's view headings (``frames`` predictions each). EXECUTION "ITEM not found"
    when every stop was searched or unreachable."""
    it = _item(ctx, item)
    prof = fetch_object_settings(ctx)
    places = {k: Pose2D(*v) for k, v in (ctx.profile.get("places") or {}).items()}
    locations = [Pose2D(*v) for v in search_settings(ctx).locations]
    try:
        stops = search_order(it, places, locations)
    except ValueError as e:
        raise SkillFailure(FailureKind.PRECONDITION, str(e)) from None
    ctx.world.pop(WORLD_TARGET, None)
    deadline = ctx.clock.now() + timeout
    views, skipped = 0, []
    for stop in stops:
        try:
            yield from drive_path(ctx, stop.pose, stop.name, timeout=max(1.0, deadline - ctx.clock.now()))
        except SkillFailure as e:
            if e.kind is not FailureKind.PLANNING:
                raise
            skipped.append(stop.name)
            ctx.emit("search_skipped", location=stop.name, reason=e.reason, node=ctx.node_path)
            continue
        heading = stop.pose.theta
        for k, dth in enumerate(prof.views):
            if k > 0:
                base = ctx.robot.base
                assert base is not None
                turn = math.remainder(heading + dth - base.state().pose.theta, math.tau)
                yield from rotate_by(ctx, turn)
            yield from _settle(ctx, prof.settle_time)
            views += 1
            t = yield from scan_for(ctx, it)
            if t is not None:
                _record(ctx, t, stop.name)
                ctx.emit("object_found", item=it.name, place=stop.name, likely=stop.likely, views=views,
                         node=ctx.node_path)
                return {"centre": [float(v) for v in t.centre], "place": stop.name,
                        "grasp": _grasp_mode(prof, it)[0], "size": list(it.size), "back_off": prof.back_off}
            if ctx.clock.now() > deadline:
                raise SkillFailure(FailureKind.EXECUTION, f"{it.name} not found within {timeout:g} s ({views} views)")
    unreachable = f" ({len(skipped)} unreachable: {', '.join(skipped)})" if skipped else ""
    raise SkillFailure(FailureKind.EXECUTION, f"{it.name} not found: {views} views at {len(stops)} places" + unreachable)


# --------------------------------------------------------------------------- approaching


def support_normal(ctx: SkillContext, xy: np.ndarray, toward: np.ndarray, reach: float = 1.0) -> tuple[float, float]:
    """Unit direction (map x, y) from an object at ``xy`` [m] to the nearest free cell of
    the robot's map within ``reach`` [m] on the side of ``toward`` (the camera it was seen
    from: within 45 degrees of that direction, so not past a shelf's side panel): out of
    its support, perpendicular to the support's nearest edge. Ties (and an object on the
    open floor) go towards ``toward``."""
    grid = ctx.robot.occupancy
    v = np.asarray(toward, dtype=float)[:2] - xy
    fallback = v / max(float(np.linalg.norm(v)), 1e-9)
    if grid is None:
        return float(fallback[0]), float(fallback[1])
    res = grid.resolution
    data = np.asarray(grid.data)
    H, W = data.shape
    ox, oy = grid.origin.x, grid.origin.y
    n = int(reach / res)
    ci, cj = int((xy[1] - oy) / res), int((xy[0] - ox) / res)
    if not (0 <= ci < H and 0 <= cj < W) or data[ci, cj] == 0:  # on the open floor: face it from the camera's side
        return float(fallback[0]), float(fallback[1])
    i0, i1, j0, j1 = max(ci - n, 0), min(ci + n + 1, H), max(cj - n, 0), min(cj + n + 1, W)
    free = data[i0:i1, j0:j1] == 0
    if not free.any():
        return float(fallback[0]), float(fallback[1])
    ii, jj = np.nonzero(free)
    px = ox + (jj + j0 + 0.5) * res - xy[0]
    py = oy + (ii + i0 + 0.5) * res - xy[1]
    d = np.hypot(px, py)
    dirs = np.stack([px, py], axis=1) / np.maximum(d, 1e-9)[:, None]
    seen = dirs @ fallback > math.cos(math.pi / 4)  # the side the camera saw it from (not past a side panel)
    if seen.any():
        d, dirs = d[seen], dirs[seen]
    k = int(np.argmin(d - 1e-3 * (dirs @ fallback)))  # the nearest free cell (ties: the camera's side)
    # the free cells along that edge (as near as the nearest plus a cell and a half, on its
    # side): their mean direction is perpendicular to the edge (the nearest cell alone is
    # off by up to half a cell); two edges as near (a corner) give the diagonal
    near = (d <= d[k] + 1.5 * res) & (dirs @ dirs[k] > 0.0)
    m = dirs[near].sum(axis=0)
    m = m / max(float(np.linalg.norm(m)), 1e-9)
    return float(m[0]), float(m[1])


def _pseudo_marker(centre: np.ndarray, normal: tuple[float, float]) -> np.ndarray:
    """A marker-convention frame at the object's centre whose z is the support's outward
    normal (for :func:`find_standoff`)."""
    z = np.array([normal[0], normal[1], 0.0])
    y = np.array([0.0, 0.0, 1.0])
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = np.cross(y, z), y, z, centre
    return T


@skill(
    "approach_object",
    params=[
        Param("distance_index", int, default=0,
              doc="start at this index of the grasp mode's standoff list (the recovery counter)"),
        Param("timeout", float, unit="s", doc="fail after this much clock time (default: profile nav.timeout)"),
    ],
    outputs=[Output("pose", list, doc="[x, y, theta] reached, map"), Output("distance", float, doc="stand-off [m]")],
    needs=("base",),
)
def approach_object(ctx: SkillContext, distance_index: int = 0, timeout: float | None = None) -> SkillGen:
    """Drive to a stand-off facing the found object from its support's free side (module
    doc), the first free and reachable of the grasp mode's distances from
    ``distance_index`` on (10 and 20 degrees either side tried too). PLANNING "no free
    stand-off" when none is."""
    t = _target(ctx, "approach_object")
    prof = fetch_object_settings(ctx)
    _, gs = _grasp_mode(prof, t.item)
    base = ctx.robot.base
    assert base is not None
    cam = (t.frame.T_map_base @ t.frame.T_base_camera)[:3, 3]
    normal = t.normal if t.normal is not None else support_normal(ctx, t.centre[:2], cam[:2])
    T = _pseudo_marker(t.centre, normal)
    dists = gs.standoff[min(max(distance_index, 0), len(gs.standoff) - 1):]
    start = base.state().pose
    cm = costmap(ctx)
    found = find_standoff(cm, T, dists, angle_offsets=(0.0, math.radians(10), -math.radians(10), math.radians(20),
                                                       -math.radians(20)), start=(start.x, start.y))
    if not found.ok or found.pose is None:
        base_status(ctx, "goal_fail", reason=found.reason or "no stand-off", item=t.item.name)
        base_status(ctx, "idle")
        raise SkillFailure(FailureKind.PLANNING, f"no free stand-off in front of {t.item.name}: {found.reason}")
    d = float(np.hypot(found.pose.x - t.centre[0], found.pose.y - t.centre[1]))
    ctx.emit("standoff", item=t.item.name, distance=round(d, 3), normal=[round(normal[0], 3), round(normal[1], 3)],
             pose=[round(found.pose.x, 3), round(found.pose.y, 3), round(found.pose.theta, 3)], node=ctx.node_path)
    path = simplify_path(cm, found.path) if found.path else None
    reached = yield from drive_path(ctx, found.pose, f"{t.item.name} stand-off",
                                    timeout=timeout if timeout is not None else nav_settings(ctx).timeout, path=path)
    return {"pose": [reached.x, reached.y, reached.theta], "distance": d}


@skill(
    "locate_object",
    params=[Param("frames", int, doc="predictions fused (default: profile fetch_object.frames)")],
    outputs=[Output("centre", list, doc="[x, y, z] of the object's centre of mass in map [m]")],
    needs=("camera",),
)
def locate_object(ctx: SkillContext, frames: int | None = None) -> SkillGen:
    """Look at the found object again from where the robot stands (the stand-off), the arm
    first in ``fetch_object.locate_pose`` when given (a wrist camera pointed down), a
    pan/tilt head aimed at the object's estimate (so the object lies in the middle of the
    image, not cut by its edge; the head goes home afterwards, or for a dangerous item
    after ``mark_dangerous`` showed the operator this view): the pick plans from this
    closest view, ``frames`` predictions fused. EXECUTION "ITEM not seen from the
    stand-off" when the aimed head's view shows no such object (the pick would close on
    nothing where the far estimate was off); a camera that cannot be aimed leaves the
    estimate the object was found with (logged, ``object_not_relocated``)."""
    t = _target(ctx, "locate_object")
    prof = fetch_object_settings(ctx)
    if prof.locate_pose is not None and ctx.robot.arm is not None:
        yield from move_named(ctx, prof.locate_pose)
    head = ctx.robot.head
    aimed = yield from _aim_head(ctx, t.centre)
    try:
        yield from _settle(ctx, prof.settle_time)
        near = yield from look_for(ctx, t.item, frames or prof.frames)
    except BaseException:
        if aimed and head is not None:
            head.point(*head.home)  # back home, not waited for (failed or cancelled)
        raise
    if aimed and head is not None and (near is None or not t.item.dangerous):
        yield from wait_goal(ctx, head.point(*head.home), timeout=10.0)
    if near is None:
        ctx.emit("object_not_relocated", item=t.item.name, distance=round(t.distance, 3), aimed=aimed,
                 node=ctx.node_path)
        if aimed:
            raise SkillFailure(FailureKind.EXECUTION, f"{t.item.name} not seen from the stand-off (the head aimed at "
                               f"its estimate {', '.join(f'{v:.2f}' for v in t.centre)} m)")
        # a camera that cannot be aimed (a wrist camera in locate_pose) may miss it from an
        # angled stand-off: the pick goes on with the estimate it was found with
        log.warning("%s not in view from its stand-off; the pick uses the estimate from %.2f m", t.item.name,
                    t.distance)
        return {"centre": [float(v) for v in t.centre]}
    if not t.item.dangerous and _more_oblique(t, near):
        # the operator of a dangerous item marks the view the robot has now: not this case
        log.info("%s: the stand-off's oblique view puts it %.3f m off the frontal estimate; keeping that",
                 t.item.name, float(np.linalg.norm(near.centre[:2] - t.centre[:2])))
        ctx.emit("object_estimate_kept", item=t.item.name, near=[round(float(v), 4) for v in near.centre],
                 kept=[round(float(v), 4) for v in t.centre], node=ctx.node_path)
        return {"centre": [float(v) for v in t.centre]}
    _record(ctx, near, "stand-off")
    return {"centre": [float(v) for v in near.centre]}


def _obliquity(t: ObjectTarget, normal: tuple[float, float]) -> float:
    """Angle [rad] between the support's outward normal and the horizontal direction from
    the object to the camera that saw it (0: seen face-on)."""
    cam = (t.frame.T_map_base @ t.frame.T_base_camera)[:2, 3]
    v = cam - t.centre[:2]
    c = float(v @ np.asarray(normal)) / max(float(np.linalg.norm(v)), 1e-9)
    return math.acos(min(1.0, max(-1.0, c)))


def _more_oblique(far: ObjectTarget, near: ObjectTarget) -> bool:
    """The closer view disagrees with the one the object was found with by more than
    :data:`RELOCATE_TOLERANCE` and saw the object more obliquely to its support's normal
    (from beside the blocker, partly hidden by a shelf's side panel: 7 cm off in the
    blocked-front campaign, while the frontal view 1.1 m away was within 1 cm)."""
    if far.normal is None or float(np.linalg.norm(near.centre[:2] - far.centre[:2])) <= RELOCATE_TOLERANCE:
        return False
    return _obliquity(near, far.normal) > _obliquity(far, far.normal)


def _head_home(ctx: SkillContext, wait: bool) -> Generator[None, None, None]:
    """A pan/tilt head off its home pose back home (``wait``: until it is there)."""
    head = ctx.robot.head
    if head is None:
        return
    st, home = head.state(), head.home
    if max(abs(st.pan - home[0]), abs(st.tilt - home[1])) <= head.tolerance:
        return
    goal = head.point(*home)
    if wait:
        yield from wait_goal(ctx, goal, timeout=10.0)


def _aim_head(ctx: SkillContext, centre: np.ndarray) -> Generator[None, None, bool]:
    """Point a pan/tilt head (one with a kinematic model) at ``centre`` (map [m]); True
    when it moved there, False without such a head or when the point is outside its
    limits (logged: the look goes on from the head's current pose)."""
    head, base = ctx.robot.head, ctx.robot.base
    if head is None or head.kinematics is None or base is None:
        return False
    p = base.state().pose
    T_base_map = np.linalg.inv(planar_transform(p.x, p.y, p.theta))
    in_base = (T_base_map @ np.array([*(float(v) for v in centre[:3]), 1.0]))[:3]
    try:
        yield from wait_goal(ctx, head.look_at(in_base), timeout=10.0)
    except SkillFailure as e:
        log.info("head not aimed at the object: %s", e.reason)
        return False
    return True


# --------------------------------------------------------------------------- dangerous items


@skill(
    "mark_dangerous",
    params=[Param("timeout", float, unit="s", doc="fail when no answer came (default: profile operator_timeout)")],
    outputs=[Output("asked", bool, doc="whether the operator was asked (the item is dangerous)")],
    needs=("camera",),
)
def mark_dangerous(ctx: SkillContext, timeout: float | None = None) -> SkillGen:
    """For an item the catalogue flags dangerous: show the operator the last frame with the
    object's box and the predicted grasp pixel (``ask_operator`` point); the grasp moves to
    the mean of the predicted and the clicked pixel (paper IV-E, Fig. 7), event
    ``grasp_corrected`` with all three pixels and the grasp centre before and after.
    Nothing to do for other items. TIMEOUT when no answer came in time."""
    t = _target(ctx, "mark_dangerous")
    if not t.item.dangerous:
        return {"asked": False}
    try:
        out = yield from _mark(ctx, t, timeout)
    except BaseException:
        yield from _head_home(ctx, wait=False)  # failed or cancelled: not waited for
        raise
    yield from _head_home(ctx, wait=True)  # locate_object left it on the object for this view
    return out


def _mark(ctx: SkillContext, t: ObjectTarget, timeout: float | None) -> SkillGen:
    limit = timeout if timeout is not None else fetch_object_settings(ctx).operator_timeout
    x, y, w, h = t.detection.box
    u, v = t.grasp.pixel
    overlay = [{"shape": "box", "points": [[x, y], [x + w, y + h]], "label": t.item.name, "color": "#ffff00"},
               {"shape": "point", "points": [[u, v]], "label": "grasp", "color": "#ff0000"}]
    answer = yield from ask_operator(ctx, kind="point", image="camera", overlay=overlay, timeout=limit,
                                     text=f"{t.item.name} is dangerous: click its dangerous part")
    clicked = answer["answer"]
    H, W = t.frame.rgb.shape[:2]
    fix = correct_grasp_pixel(t.grasp.pixel, (float(clicked[0]), float(clicked[1])), (W, H))
    try:
        moved = move_grasp(t.grasp, t.frame, fix.corrected, t.detection.box)
    except GraspPointError as e:
        raise SkillFailure(FailureKind.EXECUTION, f"{t.item.name}: the corrected grasp pixel has no depth: {e}") from None
    ctx.world[WORLD_TARGET] = moved_t = replace(t, grasp=moved, centre=moved.centre)
    ctx.world[WORLD_GRASP_FRAME] = _grasp_frame(moved_t, _grasp_mode(fetch_object_settings(ctx), t.item)[0])
    ctx.emit("grasp_corrected", item=t.item.name, predicted=list(fix.predicted), clicked=list(fix.clicked),
             corrected=list(fix.corrected), before=[round(float(c), 4) for c in t.grasp.centre],
             after=[round(float(c), 4) for c in moved.centre], source=answer["source"], node=ctx.node_path)
    return {"asked": True}


# --------------------------------------------------------------------------- picking


def _grasp_frame(t: ObjectTarget, mode: str) -> np.ndarray:
    """The grasp frame in map: the top frame as estimated; the front frame turned about
    the vertical so the gripper comes in along the support's outward normal (straight
    into a shelf, not along the view of a camera that saw it at an angle)."""
    if mode == "top" or t.normal is None:
        return t.grasp.T_map_top if mode == "top" else t.grasp.T_map_front
    nx, ny = t.normal
    T = t.grasp.T_map_front.copy()
    z = np.array([nx, ny, 0.0])
    if abs(T[2, 1]) > 0.9:  # y up: the fingers close horizontally
        y = T[:3, 1]
        T[:3, 0], T[:3, 1], T[:3, 2] = np.cross(y, z), y, z
    else:  # x up: the fingers close vertically (a flat item)
        x = T[:3, 0]
        T[:3, 0], T[:3, 1], T[:3, 2] = x, np.cross(z, x), z
    return T


@skill(
    "pick_object",
    params=planner_params(),
    outputs=[Output("item", str, doc="planning-scene name of the held object")],
    needs=("arm", "gripper"),
)
def pick_object(ctx: SkillContext, algorithm: str | None = None, time_limit: float | None = None,
                attempts: int | None = None) -> SkillGen:
    """Pick the located object: add it to the planning scene (its estimated box), plan to
    the pre-grasp (above it for a top grasp, in front for a front grasp), open, straight
    to the grasp at its centre of mass, close, attach, retract, back off, carry pose.
    POSTCONDITION when nothing is held."""
    t = _target(ctx, "pick_object")
    return (yield from with_arm_status(ctx, _pick(ctx, t, algorithm, time_limit, attempts), f"pick {t.item.name}"))


def _pick(ctx: SkillContext, t: ObjectTarget, algorithm: str | None, time_limit: float | None,
          attempts: int | None) -> SkillGen:
    try:
        return (yield from _pick_steps(ctx, t, algorithm, time_limit, attempts))
    except SkillFailure:
        ws = ctx.world.get(WORLD_ARM)
        if isinstance(ws, ArmWorkspace):
            for name in list(ws.scene.items):
                ws.scene.remove_item(name)
        ctx.world.pop(WORLD_HELD, None)
        g = ctx.robot.gripper
        if g is not None and g.state().holding:
            yield from release(ctx, arm_settings(ctx).grasp_force)
        raise


def _object_box(t: ObjectTarget) -> tuple[np.ndarray, tuple[float, float, float]]:
    """The object's estimated box in map: pose (centre, long side along x) and size."""
    g = t.grasp
    T = np.eye(4)
    c, s = math.cos(g.yaw), math.sin(g.yaw)
    T[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    T[:3, 3] = g.centre
    return T, (g.footprint[0], g.footprint[1], g.height)


def _back_off_distance(ctx: SkillContext, distance: float) -> float:
    """How far to back off from here: ``distance`` [m] when the base stands free in the
    inflated map (``back_off`` shortens it itself); when it stopped inside the inflation
    (a holistic stand-off beside the blocker) as :func:`back_off_distance` allows, as the
    holistic planner assumed (``back_off`` checks no line from a blocked start: the base
    ran into a shelf's side panel so)."""
    base = ctx.robot.base
    if base is None or ctx.robot.occupancy is None:
        return distance
    cm = costmap(ctx)
    p = base.state().pose
    if cm.is_free(p.x, p.y):
        return distance
    free = back_off_distance(cm, p, distance)
    if free < distance:
        ctx.emit("back_off_shortened", asked=round(distance, 3), used=round(free, 3), node=ctx.node_path)
    return free


def _pick_steps(ctx: SkillContext, t: ObjectTarget, algorithm: str | None, time_limit: float | None,
                attempts: int | None) -> SkillGen:
    prof, arm = fetch_object_settings(ctx), arm_settings(ctx)
    mode, gs = _grasp_mode(prof, t.item)
    ws = workspace(ctx)
    cfg = ws.config(algorithm, time_limit, attempts)
    T_am = T_armbase_map(ctx)
    name = f"object_{t.item.name}"
    T_box, size = _object_box(t)
    T_item = T_am @ T_box
    poses = grasp_poses(T_am @ _grasp_frame(t, mode), ws.kin.approach_axis, pre_grasp=gs.pre_grasp,
                        retract=gs.retract, grasp_height=gs.grasp_height, grasp_depth=gs.depth)
    q, seeds, boxes = measured_joints(ctx), ik_seeds(ctx, ws, poses.pre_grasp), ctx.robot.scene
    first = holistic_seed(ctx)  # after a holistic stand-off: its arm solution's family first
    if first is not None:
        seeds = [first, *seeds]
    ctx.emit("object_grasp", item=t.item.name, mode=mode, centre=[round(float(v), 4) for v in t.grasp.centre],
             width=round(t.grasp.top_width if mode == "top" else t.grasp.front_width, 4), node=ctx.node_path)

    def plan_pre_grasp() -> PlanResult:
        ws.scene.set_static_boxes(boxes, T_am)
        for old in list(ws.scene.items):
            ws.scene.remove_item(old)
        ws.scene.add_item(name, size, T_item)
        return ws.planner.plan_to_pose(q, poses.pre_grasp, ik_seeds=seeds, config=cfg)

    g = ctx.robot.gripper
    assert g is not None
    opening = g.open(force=arm.grasp_force)
    res = yield from off_tick(ctx, ws, plan_pre_grasp)
    ctx.emit("scene_update", op="add", item=name, node=ctx.node_path)
    pre = planned(ctx, res, "pre-grasp")
    yield from wait_goal(ctx, opening, timeout=GRIPPER_TIMEOUT)
    yield from execute(ctx, pre, "pre-grasp")
    q = measured_joints(ctx)

    def plan_approach() -> PlanResult:
        ws.scene.remove_item(name)  # the fingers must touch it
        return ws.planner.cartesian_path(q, poses.grasp, config=cfg)

    grasp = planned(ctx, (yield from off_tick(ctx, ws, plan_approach)), "grasp approach")
    yield from execute(ctx, grasp, "grasp approach")
    yield from wait_goal(ctx, g.close(force=arm.grasp_force), timeout=GRIPPER_TIMEOUT)
    held, why = holding(ctx, arm.min_held_width)
    if not held:
        yield from release(ctx, arm.grasp_force)
        raise SkillFailure(FailureKind.POSTCONDITION, f"nothing held after closing on {t.item.name} ({why})")
    q_grasp = measured_joints(ctx)

    def plan_retract() -> PlanResult:
        held_size = tuple(max(s - 2.0 * HELD_CLEARANCE, 0.5 * s) for s in size)
        ws.scene.add_item(name, held_size, T_item)  # type: ignore[arg-type]
        ws.scene.attach_item(name, q_grasp)
        try:
            ws.scene.clear_attached_from_static(name, q_grasp)
        except ValueError as e:
            log.info("retract: %s", e)
        line = ws.planner.cartesian_path(q_grasp, poses.retract, config=cfg)
        if not line.success and line.reason != CANCELLED:
            line = ws.planner.plan_to_pose(q_grasp, poses.retract, ik_seeds=[q_grasp], config=cfg)
        return line

    ctx.world[WORLD_HELD] = name
    line = yield from off_tick(ctx, ws, plan_retract)
    ctx.emit("scene_update", op="attach", item=name, node=ctx.node_path)
    yield from execute(ctx, planned(ctx, line, "retract"), "retract")
    if ctx.robot.base is not None and prof.back_off > 0:
        yield from back_off(ctx, _back_off_distance(ctx, prof.back_off))
    yield from move_named(ctx, arm.carry, cfg=cfg)
    held, why = holding(ctx, arm.min_held_width)
    if not held:
        raise SkillFailure(FailureKind.POSTCONDITION, f"{t.item.name} lost after lifting it ({why})")
    return {"item": name}

