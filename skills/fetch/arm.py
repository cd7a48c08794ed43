"""The fetch mission's arm skills: pick the box tagged with the requested marker and place
it in the depot basket, with the seed paper's poses. They are built from the general arm
library (:mod:`mmexec.skills.manipulation.arm`: planning off the tick against the
planning scene, execution, gripper checks, ``arm_status`` events) and read the profile's
``arm:`` section (gripper force and closed width, carry and stow poses, planner) and
``fetch:`` section (the item's size and grasp offsets, the depot).

Planning-scene updates follow the seed: the item is **added** when perceived (at the start
of ``pick``), **attached** to the gripper on grasp, **detached** and **removed** on
place.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator, Iterator, Sequence

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
from mmexec.skills.fetch.profile import FetchProfile, fetch_profile
from mmexec.skills.manipulation import (
    CANCELLED,
    GraspPoses,
    PlacePoses,
    PlannerConfig,
    PlanResult,
    grasp_poses,
    place_poses,
)
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
from mmexec.skills.manipulation.holistic_skill import holistic_seed
from mmexec.skills.navigation.navigate import back_off
from mmexec.skills.perception.detect import (
    MarkerEstimate,
    camera_settings,
    emit_estimate,
    look,
    markers,
)

__all__ = ["pick", "place"]

log = logging.getLogger(__name__)

#: [m] per side: a held item is modelled this much smaller than ``fetch.item_size``, so
#: the support it was lifted from (touching it, give or take the marker estimate's error)
#: does not count as a collision at the start of the retract.
HELD_CLEARANCE = 0.005

#: [m] release heights above the profile's place pose, tried in order: a held item that
#: sits a little off its planned hold can have no collision-free IK at the nominal height
#: (the basket wall, the robot's own body) and is then dropped from a little higher.
PLACE_RAISES = (0.0, 0.05, 0.10)

#: An attached item whose longest side is at least this many times its next longest is
#: *elongated*: a tool (a screwdriver, pliers, a pen: 3.5-4.8 by their catalogue sizes),
#: not a box or a can standing up (1.6-1.8; 2.0 as held, each side 1 cm smaller).
ELONGATED = 3.0

#: The tool axis the fingers travel along (the WX250s and the Robotiq alike:
#: skills/manipulation/grasp.py).
FINGER_AXIS = 1

#: Releases at the place pose before place gives up on an item that stays in the gripper:
#: after each release and retract the fingers close to stow; closing on something means the
#: released item came along (caught on the fingers), so it is taken back down and let go again.
PLACE_RELEASES = 3

#: [m] with a camera on the arm (profile ``arm.look`` set), a marker estimate seen from
#: farther than this is looked at again from close before the pick plans its grasp
#: (:func:`_look_closer`): the UR3e's wrist camera does not see the lower board from its
#: stand-off, and an estimate from 1.25 m was 2.5 cm off sideways and 1.9 cm in depth,
#: enough to grasp the box off-centre and drop it on the way to the carry pose.
LOOK_CLOSER_FROM = 0.9

#: The camera poses of that look, tried in order: [m] from the marker along its normal,
#: [m] above its centre, the camera's optical axis through the marker centre; each also
#: rolled 0, 180, 90 and -90 degrees about that axis (:data:`CLOSE_LOOK_ROLLS`). The UR3e
#: at a 0.74 m stand-off reaches a lower-board marker's 0.35 m views, 5-15 cm up, not the
#: level ones from 0.4 m or more (the arm would fold back over the base).
CLOSE_LOOKS = ((0.35, 0.15), (0.35, 0.05), (0.40, 0.20), (0.30, 0.10))
CLOSE_LOOK_ROLLS = (0.0, math.pi, math.pi / 2, -math.pi / 2)

#: [s] the arm rests this long at the close look before the camera's frames are taken
CLOSE_LOOK_SETTLE = 0.3

#: The retracts :func:`_free_retract` falls back to, in order, when the profile's is not
#: free: straight up (map z) by the profile retract's length; up as much and half of it
#: away from the base (over the basket).
RETRACT_WAYS = ("up", "up and out")


def _item_pose_and_size(prof: FetchProfile, T_marker: np.ndarray) -> tuple[np.ndarray, tuple[float, float, float]]:
    """Box centre pose (marker axes) and size along the marker's x, y, z for an item
    whose marker is on its +x face: the box lies behind the face (along -z)."""
    sx, sy, sz = prof.item_size
    off = np.eye(4)
    off[2, 3] = -sx / 2.0
    return T_marker @ off, (sy, sz, sx)


@skill(
    "pick",
    params=[Param("marker", int, required=True, doc="marker id of the item (its estimate is in the world model)"),
            *planner_params()],
    outputs=[Output("item", str, doc="planning-scene name of the held item")],
    needs=("arm", "gripper"),
)
def pick(ctx: SkillContext, marker: int, algorithm: str | None = None, time_limit: float | None = None,
         attempts: int | None = None) -> SkillGen:
    """Seed pick routine in the marker frame: add the item to the planning scene; plan to
    the pre-grasp (profile fetch.pre_grasp, default (0, 0, 0.10) m); open; straight in to
    the grasp (marker face, grasp_depth behind it, fingers horizontal); close; attach the
    item; straight out to the retract pose; carry pose. POSTCONDITION "nothing held"
    when the gripper closed on nothing."""
    return (yield from with_arm_status(ctx, _pick(ctx, marker, algorithm, time_limit, attempts), f"pick marker {marker}"))


def _pick(ctx: SkillContext, marker: int, algorithm: str | None, time_limit: float | None,
          attempts: int | None) -> SkillGen:
    try:
        return (yield from _pick_steps(ctx, marker, algorithm, time_limit, attempts))
    except SkillFailure:
        # leave nothing half-done for the recovery: release what the gripper may hold and
        # clear the scene of the item (a retry perceives and adds it again)
        ws = ctx.world.get(WORLD_ARM)
        if isinstance(ws, ArmWorkspace):
            for name in list(ws.scene.items):
                ws.scene.remove_item(name)
        ctx.world.pop(WORLD_HELD, None)
        g = ctx.robot.gripper
        if g is not None and g.state().holding:
            yield from release(ctx, arm_settings(ctx).grasp_force)
        raise


def _pick_steps(ctx: SkillContext, marker: int, algorithm: str | None, time_limit: float | None,
                attempts: int | None) -> SkillGen:
    prof, arm = fetch_profile(ctx), arm_settings(ctx)
    est = markers(ctx).get(marker)
    if est is None:
        raise SkillFailure(FailureKind.PRECONDITION, f"pick: no estimate of marker {marker} (detect it first)")
    ws = workspace(ctx)
    cfg = ws.config(algorithm, time_limit, attempts)
    T_am = T_armbase_map(ctx)
    if arm.look is not None and ctx.robot.camera is not None and est.distance > LOOK_CLOSER_FROM:
        est = yield from _look_closer(ctx, ws, cfg, marker, est, T_am)
    T_am_marker = T_am @ est.T_map_marker
    name = f"item_{marker}"
    T_item, size = _item_pose_and_size(prof, T_am_marker)
    poses = grasp_poses(T_am_marker, ws.kin.approach_axis, pre_grasp=prof.pre_grasp, grasp_depth=prof.grasp_depth,
                        retract=prof.retract, grasp_height=prof.grasp_height)
    q, seeds, boxes = measured_joints(ctx), ik_seeds(ctx, ws, poses.pre_grasp), ctx.robot.scene
    first = holistic_seed(ctx)  # after a holistic stand-off: its arm solution's family first
    if first is not None:
        seeds = [first, *seeds]

    def plan_pre_grasp() -> PlanResult:
        ws.scene.set_static_boxes(boxes, T_am)
        for old in list(ws.scene.items):
            ws.scene.remove_item(old)
        ws.scene.add_item(name, size, T_item)
        return _plan_pre_grasp(ws, q, poses, seeds, cfg, name, size, T_item, changed)

    changed: list[tuple[int, str]] = []  # (solution, the first's reason) when not the first
    g = ctx.robot.gripper
    assert g is not None
    opening = g.open(force=arm.grasp_force)  # opens while the plan is computed
    res = yield from off_tick(ctx, ws, plan_pre_grasp)
    ctx.emit("scene_update", op="add", item=name, node=ctx.node_path)
    pre = planned(ctx, res, "pre-grasp")
    for solution, first in changed:
        ctx.emit("pre_grasp_changed", solution=solution, first=first, node=ctx.node_path)
    yield from wait_goal(ctx, opening, timeout=GRIPPER_TIMEOUT)
    yield from execute(ctx, pre, "pre-grasp")
    q = measured_joints(ctx)

    def plan_approach() -> PlanResult:
        # the fingers must touch the item: take it out of the scene for the straight approach
        ws.scene.remove_item(name)
        return ws.planner.cartesian_path(q, poses.grasp, config=cfg)

    grasp = planned(ctx, (yield from off_tick(ctx, ws, plan_approach)), "grasp approach")
    yield from execute(ctx, grasp, "grasp approach")
    yield from wait_goal(ctx, g.close(force=arm.grasp_force), timeout=GRIPPER_TIMEOUT)
    held, why = holding(ctx, arm.min_held_width)
    if not held:
        yield from release(ctx, arm.grasp_force)
        raise SkillFailure(FailureKind.POSTCONDITION, f"nothing held after closing on marker {marker} ({why})")
    q_grasp = measured_joints(ctx)

    def plan_retract() -> PlanResult:
        # the held item rests on its board: modelled from the marker estimate, a few mm
        # of estimate error would put it into the board and fail the retract's start
        sx, sy, sz = (max(s - 2.0 * HELD_CLEARANCE, 0.5 * s) for s in size)
        held_size = (sx, sy, sz)
        ws.scene.add_item(name, held_size, T_item)
        ws.scene.attach_item(name, q_grasp)
        try:
            shift = ws.scene.clear_attached_from_static(name, q_grasp)
        except ValueError as e:  # deeper than estimate error: let the planner report the collision
            log.info("retract: %s", e)
        else:
            if shift > 0:
                log.info("retract: held %s model moved %.1f mm out of the support it was lifted from",
                         name, shift * 1e3)
        line = ws.planner.cartesian_path(q_grasp, poses.retract, config=cfg)
        if not line.success and line.reason != CANCELLED:
            # the straight line folds the arm into itself: plan a way instead
            log.info("retract: %s; planning to the retract pose", line.reason)
            line = ws.planner.plan_to_pose(q_grasp, poses.retract, ik_seeds=[q_grasp], config=cfg)
        return line

    ctx.world[WORLD_HELD] = name
    line = yield from off_tick(ctx, ws, plan_retract)
    ctx.emit("scene_update", op="attach", item=name, node=ctx.node_path)
    out = planned(ctx, line, "retract")
    yield from execute(ctx, out, "retract")
    if ctx.robot.base is not None:
        # leave the shelf before folding the arm: the carry pose sticks out in front
        yield from back_off(ctx, prof.back_off)
    yield from move_named(ctx, arm.carry, cfg=cfg)
    held, why = holding(ctx, arm.min_held_width)
    if not held:
        raise SkillFailure(FailureKind.POSTCONDITION, f"item of marker {marker} lost after lifting it ({why})")
    return {"item": name}


def _look_closer(ctx: SkillContext, ws: ArmWorkspace, cfg: PlannerConfig, marker: int, est: MarkerEstimate,
                 T_am: np.ndarray) -> Generator[None, None, MarkerEstimate]:
    """Move the arm's camera to look at marker ``marker`` from close (:data:`CLOSE_LOOKS`:
    the first camera pose with a collision-free plan, the item from the estimate in the
    scene) and look again; seen: the new estimate (event ``marker_estimate``), else the
    old one. Event ``pick_look`` (marker, seen, estimated_from: the old estimate's distance [m],
    camera: the camera-marker distance of the pose used, or None when none was reachable)."""
    prof = fetch_profile(ctx)
    cam = ctx.robot.camera
    assert cam is not None
    arm = ctx.robot.arm
    assert arm is not None
    q = measured_joints(ctx)
    # the camera in the tool frame, from where both are now (the camera rides on the arm)
    T_tool_cam = (np.linalg.inv(ws.kin.fk(q)) @ np.linalg.inv(np.asarray(arm.mount, dtype=float))
                  @ np.asarray(cam.pose_in_base(), dtype=float))
    T_am_marker = T_am @ est.T_map_marker
    T_item, size = _item_pose_and_size(prof, T_am_marker)
    name = f"item_{marker}"
    boxes = ctx.robot.scene
    used: list[float] = []

    def plan_look() -> PlanResult:
        ws.scene.set_static_boxes(boxes, T_am)
        for old in list(ws.scene.items):
            ws.scene.remove_item(old)
        ws.scene.add_item(name, size, T_item)
        res = PlanResult(False, "no collision-free IK for any camera pose")
        try:
            for dist, up in CLOSE_LOOKS:
                for roll in CLOSE_LOOK_ROLLS:
                    T_tool = _camera_aimed(T_am_marker, dist, up, roll) @ np.linalg.inv(T_tool_cam)
                    if ws.planner.stop.is_set():
                        return PlanResult(False, CANCELLED)
                    sol = ws.kin.ik(T_tool, q, attempts=20, is_valid=ws.scene.is_valid)
                    if sol is None:
                        continue
                    res = ws.planner.plan(q, _nearest_turns(sol, q, ws.kin.lower, ws.kin.upper), cfg)
                    if res.success or res.reason == CANCELLED:
                        used.append(dist)
                        return res
        finally:
            ws.scene.remove_item(name)
        return res

    res = yield from off_tick(ctx, ws, plan_look)
    if not res.success or res.trajectory is None:
        log.info("pick: no close look at marker %d (%s); the estimate from %.2f m stays", marker, res.reason,
                 est.distance)
        ctx.emit("pick_look", marker=marker, seen=False, estimated_from=round(est.distance, 3), camera=None,
                 node=ctx.node_path)
        return est
    yield from execute(ctx, planned(ctx, res, "close look"), "close look")
    end = ctx.clock.now() + CLOSE_LOOK_SETTLE
    while ctx.clock.now() < end - 1e-9:
        yield
    new = yield from look(ctx, marker, camera_settings(ctx).detect_frames)
    ctx.emit("pick_look", marker=marker, seen=new is not None, estimated_from=round(est.distance, 3),
             camera=used[0] if used else None, node=ctx.node_path)
    if new is None:
        log.info("pick: marker %d not seen from the close look; the estimate from %.2f m stays", marker, est.distance)
        return est
    emit_estimate(ctx, new)
    return new


def _nearest_turns(q: np.ndarray, ref: Sequence[float], lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``q`` [rad] with each joint moved by whole turns to the value nearest ``ref``
    within [``lower``, ``upper``] (the same tool pose). The IK can return a UR wrist joint
    (range +-2 turns) a turn away from where it is: from the UR3e's look pose
    to a lower-board pre-grasp, wrist 1 went from -4.1 to +4.82 rad instead of -1.46 and
    wrist 3 from 0 to -4.71 instead of +1.57, a 5.7 s motion sweeping the gripper round
    (the target stage's upper board touched in 3-4 of 20 corridors trials, a passer-by in
    one lab crowd trial)."""
    out = np.array(q, dtype=float)
    for i, (v, r, lo, hi) in enumerate(zip(out, ref, lower, upper)):
        turns = [v + k * math.tau for k in range(-3, 4)]
        inside = [c for c in turns if lo - 1e-9 <= c <= hi + 1e-9]
        out[i] = min(inside, key=lambda c: abs(c - float(r)))
    return out


def _camera_aimed(T_marker: np.ndarray, dist: float, up: float, roll: float) -> np.ndarray:
    """A camera (optical) pose, same frame as ``T_marker``: ``dist`` [m] out along the
    marker's normal and ``up`` [m] higher, its z through the marker's centre, its x
    horizontal (to the right, y down: the image upright), turned by ``roll`` [rad] about z."""
    c = T_marker[:3, 3] + T_marker[:3, 2] * dist + np.array([0.0, 0.0, up])
    z = T_marker[:3, 3] - c
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])  # image x to the right, y down: upright
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    cr, sr = math.cos(roll), math.sin(roll)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = cr * x + sr * y, -sr * x + cr * y, z, c
    return T


def _plan_pre_grasp(ws: ArmWorkspace, q: list[float], poses: GraspPoses, seeds: list[list[float]],
                    cfg: PlannerConfig, name: str, size: tuple[float, float, float],
                    T_item: np.ndarray, changed: list[tuple[int, str]] | None = None) -> PlanResult:
    """(worker thread) A plan to the pre-grasp (arm base frame) whose IK solution the
    straight grasp approach can start from: the collision-free IK solutions of the
    pre-grasp in turn (:func:`_pre_grasp_solutions`: the seeds' first, as
    ``plan_to_pose`` finds them, each joint the whole turns nearest where the arm is),
    each kept only when the straight line to the grasp
    (the item ``name`` out of the scene: the fingers touch it) is continuous and free.
    The UR3e near the end of its reach has two families at a lower-board pre-grasp, and
    from the one a seed can fall into (shoulder down) the line meets a singularity or
    folds the forearm into the base (the UR3e lab crowd trial 8, seed 294338835; seed
    269668801: 'joint jump' and 'forearm vs mobile_base_link at 86 %'), while from the
    other it is free. When no solution's line is free, PLANNING "grasp approach: REASON"
    before the arm moves (REASON the first solution's). ``changed`` gets (the solution's
    1-based number, the first one's reason) when the plan is not to the first solution."""
    first_line: PlanResult | None = None
    tried = 0
    for q_goal in _pre_grasp_solutions(ws, q, poses.pre_grasp, seeds):
        if ws.planner.stop.is_set():
            return PlanResult(False, CANCELLED)
        tried += 1
        ws.scene.remove_item(name)
        try:
            line = ws.planner.cartesian_path(q_goal, poses.grasp, config=cfg)
        finally:
            ws.scene.add_item(name, size, T_item)
        if line.success:
            if first_line is not None:
                log.info("pre-grasp: IK solution %d of the pre-grasp is the first the grasp approach is free from "
                         "(the first: %s)", tried, first_line.reason)
                if changed is not None:
                    changed.append((tried, first_line.reason))
            return ws.planner.plan(q, q_goal, cfg)
        if line.reason == CANCELLED:
            return line
        first_line = first_line or line
    if first_line is None:  # no collision-free IK: plan_to_pose's own reason
        return ws.planner.plan_to_pose(q, poses.pre_grasp, ik_seeds=seeds, config=cfg)
    return PlanResult(False, f"grasp approach: {first_line.reason} (from every one of {tried} IK solutions "
                             f"of the pre-grasp)", first_line.planning_time)


#: random IK starts :func:`_pre_grasp_solutions` tries after the seeds (deterministic:
#: the IK's own generator seeded 0, 1, ...)
PRE_GRASP_STARTS = 40


def _pre_grasp_solutions(ws: ArmWorkspace, q: list[float], T: np.ndarray,
                         seeds: list[list[float]]) -> Iterator[np.ndarray]:
    """(worker thread) Distinct collision-free IK solutions [rad] of the tool pose ``T``
    (arm base): from each of ``seeds`` in turn, then from ``q`` with restarts (the order
    ``ArmPlanner.plan_to_pose`` takes, so its goal comes first), then from
    :data:`PRE_GRASP_STARTS` random starts; each joint the whole turns nearest ``q``
    (:func:`_nearest_turns`). Two solutions are the same when no joint differs by more
    than 0.05 rad (angles compared modulo a turn)."""
    kin, valid = ws.kin, ws.scene.is_valid
    found: list[np.ndarray] = []

    def new(sol: np.ndarray | None) -> bool:
        if sol is None:
            return False
        if any(float(np.max(np.abs(np.remainder(sol - f + math.pi, math.tau) - math.pi))) < 0.05 for f in found):
            return False
        found.append(sol)
        return True

    def near(sol: np.ndarray | None) -> np.ndarray | None:
        return None if sol is None else _nearest_turns(sol, q, kin.lower, kin.upper)

    for s in seeds:
        sol = near(kin.ik(T, s, attempts=1, is_valid=valid))
        if new(sol):
            yield sol
    sol = near(kin.ik(T, q, attempts=20, is_valid=valid))
    if new(sol):
        yield sol
    for k in range(PRE_GRASP_STARTS):
        if ws.planner.stop.is_set():
            return
        sol = near(kin.ik(T, None, seed=k, attempts=1, is_valid=valid))
        if new(sol):
            yield sol


def _place_frame(place: Sequence[float], base_xy: tuple[float, float]) -> np.ndarray:
    """Place frame in map (marker convention): origin at ``place``, z horizontal towards
    the base, y up, x = y x z."""
    px, py, pz = (float(v) for v in place)
    z = np.array([base_xy[0] - px, base_xy[1] - py, 0.0])
    n = float(np.linalg.norm(z))
    z = z / n if n > 1e-6 else np.array([1.0, 0.0, 0.0])
    y = np.array([0.0, 0.0, 1.0])
    x = np.cross(y, z)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, (px, py, pz)
    return T


@skill("place", params=planner_params(), outputs=[Output("item", str, doc="the item released")],
       needs=("arm", "gripper"))
def place(ctx: SkillContext, algorithm: str | None = None, time_limit: float | None = None,
          attempts: int | None = None) -> SkillGen:
    """Seed place routine at the depot (the base must be at the depot pose): plan to the
    place pose (profile fetch.depot.place, the item's centre; the tool turned about its
    approach as little as possible from how it carried the item, :data:`PLACE_ROLLS`);
    check the item is still held; open; detach and remove the item from the planning
    scene; retract (profile fetch.place_retract, default (0, 0, 0.10) m in the place
    frame; where that straight line is not free, straight up or up and out instead:
    :func:`_free_retract`); close, and check the fingers closed on nothing: when they close on the item
    (it came along, caught on the fingers), go back down, open and retract again, at
    most :data:`PLACE_RELEASES` releases in all, then POSTCONDITION with the item held;
    stow the arm."""
    return (yield from with_arm_status(ctx, _place(ctx, algorithm, time_limit, attempts), "place"))


def _place(ctx: SkillContext, algorithm: str | None, time_limit: float | None, attempts: int | None) -> SkillGen:
    prof, arm = fetch_profile(ctx), arm_settings(ctx)
    held, why = holding(ctx, arm.min_held_width)
    if not held:
        raise SkillFailure(FailureKind.PRECONDITION, f"place: nothing held ({why})")
    ws = workspace(ctx)
    cfg = ws.config(algorithm, time_limit, attempts)
    T_am = T_armbase_map(ctx)
    name = str(ctx.world.get(WORLD_HELD, "item"))
    base = ctx.robot.base
    bp = base.state().pose if base is not None else None
    T_map_place = _place_frame(prof.depot.place, (bp.x, bp.y) if bp is not None else (0.0, 0.0))
    # the nominal release height first; when the held item (not always held exactly as
    # planned) has no collision-free IK there, release it a little higher above the basket
    candidates = [(raise_by, place_poses(T_am @ _raised(T_map_place, raise_by), ws.kin.approach_axis,
                                         retract=prof.place_retract, grasp_height=prof.grasp_height))
                  for raise_by in PLACE_RAISES]
    q = measured_joints(ctx)
    T_tool = ws.kin.fk(q)
    item = ws.scene.items.get(name)
    if (item is not None and item.attached and _resting_on_a_finger(T_tool)
            and _stood_up(item.size, item.T, candidates[0][1].place)):
        # the item rests on the lower finger (the UR carry: fingers closing vertically) and
        # the nominal pose would stand it on end, hanging in a horizontal pinch: release it
        # lying, from above, as carried (only where the arm can also retract from there).
        # A carry that pinches horizontally already (the LoCoBot's) keeps the nominal release.
        top_down = [(raise_by, td) for raise_by, nominal in candidates
                    for td in _top_down(T_tool, item.T, (T_am @ _raised(T_map_place, raise_by))[:3, 3],
                                        nominal.retract[:3, 3] - nominal.place[:3, 3], ws.kin.approach_axis)]
        candidates = top_down + candidates
    else:
        top_down = []
    seeds, boxes = ik_seeds(ctx, ws, candidates[0][1].place), ctx.robot.scene
    chosen: list[tuple[float, PlacePoses]] = []

    def plan_place() -> PlanResult:
        ws.scene.set_static_boxes(boxes, T_am)
        res = None
        for i, cand in enumerate(candidates):
            res = ws.planner.plan_to_pose(q, cand[1].place, ik_seeds=seeds, config=cfg)
            if res.success and i < len(top_down) and res.path:
                back = ws.planner.cartesian_path(res.path[-1], cand[1].retract, config=cfg)
                if not back.success:
                    res = PlanResult(False, f"no retract from it ({back.reason})")
            if res.success:
                chosen.append(cand)
                break
            if res.reason == CANCELLED:
                break
        assert res is not None
        return res

    res = planned(ctx, (yield from off_tick(ctx, ws, plan_place)), "place pose")
    raised, poses = chosen[0]
    if raised > 0:
        ctx.emit("place_raised", by=raised, node=ctx.node_path)
    if any(poses is td for _, td in top_down):
        ctx.emit("place_from_above", item=name, node=ctx.node_path)
    yield from execute(ctx, res, "place pose")
    held, why = holding(ctx, arm.min_held_width)
    if not held:  # dropped on the way (the gripper says so): releasing would report a delivery that is not
        raise SkillFailure(FailureKind.POSTCONDITION, f"place: {name} lost before the place pose ({why})")
    yield from release(ctx, arm.grasp_force)
    q = measured_joints(ctx)

    def plan_back() -> tuple[PlanResult, str]:
        if name in ws.scene.items:
            ws.scene.detach_item(name, q)
            ws.scene.remove_item(name)
        return _free_retract(ws, q, poses, cfg)

    ctx.world.pop(WORLD_HELD, None)
    back, way = yield from off_tick(ctx, ws, plan_back)
    ctx.emit("scene_update", op="detach_remove", item=name, node=ctx.node_path)
    yield from _retract(ctx, back, way)
    g = ctx.robot.gripper
    assert g is not None
    for release_no in range(1, PLACE_RELEASES + 1):
        yield from wait_goal(ctx, g.close(force=arm.grasp_force), timeout=GRIPPER_TIMEOUT)
        caught, _ = holding(ctx, 0.0)
        if not caught:  # the fingers closed on nothing: the item stayed in the basket
            break
        width = g.state().width
        ctx.world[WORLD_HELD] = name  # held again: never stow (or report) it as delivered
        ctx.emit("place_item_caught", item=name, release=release_no, width=round(width, 4), node=ctx.node_path)
        if release_no == PLACE_RELEASES:
            raise SkillFailure(FailureKind.POSTCONDITION,
                               f"place: {name} still in the gripper after {PLACE_RELEASES} releases "
                               f"(it closed on it at {width * 1e3:.0f} mm)")
        # down again, turned half a turn about the approach every other time: an item
        # hanging from the fingers by its wider end goes back with that end down
        turn = math.pi if release_no % 2 else 0.0
        again = PlacePoses(_rolled(poses.place, ws.kin.approach_axis, turn),
                           _rolled(poses.retract, ws.kin.approach_axis, turn))
        log.info("place: %s came along after release %d (closed at %.0f mm): down again, turned %.0f deg",
                 name, release_no, width * 1e3, math.degrees(turn))
        q = measured_joints(ctx)
        down = yield from off_tick(ctx, ws, lambda q=q, T=again.place: _plan_again(ws, q, T, cfg))
        yield from execute(ctx, planned(ctx, down, "place again"), "place again")
        yield from release(ctx, arm.grasp_force)
        ctx.world.pop(WORLD_HELD, None)
        q = measured_joints(ctx)
        up, way = yield from off_tick(ctx, ws, lambda q=q, p=again: _free_retract(ws, q, p, cfg))
        yield from _retract(ctx, up, way)
    yield from move_named(ctx, arm.stow, cfg=cfg)
    return {"item": name}


def _free_retract(ws: ArmWorkspace, q: list[float], poses: PlacePoses, cfg: PlannerConfig) -> tuple[PlanResult, str]:
    """(worker thread) A collision-free straight retract of the open gripper from the
    release pose at ``q`` (arm base frame): the profile's (``poses.retract``) when it is
    free, else (:data:`RETRACT_WAYS`) straight up by as much, else up by as much and half
    that away from the base, else a plan to the pose straight up. A base that stopped
    closer to the basket than its depot pose leaves the arm folded over the release
    point, and the profile's retract, back towards the base, folds it into the camera
    tower (the LoCoBot lab crowd row, trials 107 and 132: 6 cm short); up, the fingers
    leave the released item all the same. Returns the plan and which way it is (the
    first that was free, or the profile's failure)."""
    T0 = ws.kin.fk(q)
    back = poses.retract[:3, 3] - T0[:3, 3]
    length = float(np.linalg.norm(back))
    up = np.array([0.0, 0.0, length])
    away = np.array([-back[0], -back[1], 0.0]) * 0.5
    first = ws.planner.cartesian_path(q, poses.retract, config=cfg)
    if first.success or first.reason == CANCELLED or length < 1e-6:
        return first, "profile"
    tried = [back]
    for way, offset in zip(RETRACT_WAYS, (up, up + away)):
        if any(float(np.linalg.norm(offset - o)) < 1e-3 for o in tried):
            continue  # the profile's retract is already straight up (a release from above)
        tried.append(offset)
        T = T0.copy()
        T[:3, 3] += offset
        res = ws.planner.cartesian_path(q, T, config=cfg)
        if res.success or res.reason == CANCELLED:
            return res, way
    T = T0.copy()
    T[:3, 3] += up
    res = ws.planner.plan_to_pose(q, T, ik_seeds=[q], config=cfg)
    if res.success or res.reason == CANCELLED:
        return res, "planned up"
    return first, "profile"


def _retract(ctx: SkillContext, res: PlanResult, way: str) -> Generator[None, None, None]:
    """Execute a retract :func:`_free_retract` chose (event ``place_retract_changed``
    when it is not the profile's), or fail PLANNING with the profile's reason."""
    if way != "profile" and res.success:
        log.info("place: the profile's retract is not free; retracting %s", way)
        ctx.emit("place_retract_changed", way=way, node=ctx.node_path)
    yield from execute(ctx, planned(ctx, res, "place retract"), "place retract")


def _raised(T: np.ndarray, by: float) -> np.ndarray:
    """``T`` moved up by ``by`` [m] (map z)."""
    out = T.copy()
    out[2, 3] += by
    return out


def _rolled(T: np.ndarray, approach_axis: int, angle: float) -> np.ndarray:
    """Tool pose ``T`` turned by ``angle`` [rad] about its own approach axis (same origin)."""
    c, s = math.cos(angle), math.sin(angle)
    i, j = (approach_axis + 1) % 3, (approach_axis + 2) % 3
    R = np.eye(4)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return T @ R


def _resting_on_a_finger(T_tool: np.ndarray) -> bool:
    """Whether the fingers of the tool at ``T_tool`` (arm base, z up) close within 45
    degrees of the vertical, so a held item rests on the lower one. Both arms' fingers
    travel along the tool's y (skills/manipulation/grasp.py)."""
    return abs(float(T_tool[2, FINGER_AXIS])) > math.cos(math.radians(45.0))


def _stood_up(size: Sequence[float], T_tool_item: np.ndarray, T_place: np.ndarray) -> bool:
    """Whether an attached item of box ``size`` [m] held at ``T_tool_item`` is elongated
    (:data:`ELONGATED`) and the tool pose ``T_place`` (arm base, z up) turns its longest
    side within 45 degrees of the vertical."""
    k = int(np.argmax(size))
    rest = sorted(float(v) for v in size)[:2]
    if float(size[k]) < ELONGATED * rest[1]:
        return False
    return abs(float((T_place[:3, :3] @ T_tool_item[:3, k])[2])) > math.cos(math.radians(45.0))


def _top_down(T_tool: np.ndarray, T_tool_item: np.ndarray, centre: np.ndarray, lift: np.ndarray,
              approach_axis: int) -> list[PlacePoses]:
    """Release poses (arm base, z up) with the tool's approach pointing straight down: the
    current tool orientation ``T_tool`` tilted the shortest way until its approach is
    vertical (an item lying across the fingers stays lying), then turned about the
    vertical by 0, 90, -90 and 180 degrees; each placed so the held item's centre
    (``T_tool_item``) is at ``centre`` [m], and retracted by ``lift`` [m]."""
    a = T_tool[:3, approach_axis]
    down = np.array([0.0, 0.0, -1.0])
    axis = np.cross(a, down)
    s, c = float(np.linalg.norm(axis)), float(a @ down)
    if s > 1e-9:
        K = _skew(axis / s)
    else:  # pointing straight down already (no tilt), or straight up (half a turn)
        K = _skew(T_tool[:3, (approach_axis + 1) % 3]) if c < 0.0 else np.zeros((3, 3))
    R_tilt = np.eye(3) + s * K + (1.0 - c) * K @ K
    out = []
    for yaw in (0.0, math.pi / 2, -math.pi / 2, math.pi):
        cy, sy = math.cos(yaw), math.sin(yaw)
        R = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]]) @ R_tilt @ T_tool[:3, :3]
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, centre - R @ T_tool_item[:3, 3]
        T_r = T.copy()
        T_r[:3, 3] += lift
        out.append(PlacePoses(T, T_r))
    return out


def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _plan_again(ws: ArmWorkspace, q: list[float], T: np.ndarray, cfg: PlannerConfig) -> PlanResult:
    """(worker thread) From the retract back to the place pose ``T`` (arm base): the
    straight line when the tool keeps its turn, else a plan."""
    line = ws.planner.cartesian_path(q, T, config=cfg)
    if line.success or line.reason == CANCELLED:
        return line
    return ws.planner.plan_to_pose(q, T, ik_seeds=[q], config=cfg)
