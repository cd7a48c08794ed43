"""Arm skills of the fetch mission: pick and place with the seed paper's poses, every
motion planned (IK + OMPL, RRTConnect by default, RRT* selectable) against a planning
scene made of the robot's static boxes (``robot.scene``) plus the perceived item, and
executed with ``robot.arm.follow(trajectory)``.

Planning-scene updates follow the seed: the item is **added** when perceived (at the start
of ``pick``), **attached** to the gripper on grasp, **detached** and **removed** on
place. Arm states are emitted as ``arm_status`` events: ``running``, ``success``,
``fail`` (with the reason) and ``idle``.

Frames: poses are computed in ``map`` from the marker estimate, then moved into the arm
base frame through the base pose (odometry) and the arm mount:
``T_armbase_map = inv(T_map_base @ T_base_armbase)``.
"""

from __future__ import annotations

import logging
import math
import weakref
from collections.abc import Callable, Generator, Sequence
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from mmexec.drivers.interfaces import GraspState
from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillCancelled,
    SkillContext,
    SkillFailure,
    skill,
    wait_goal,
)
from mmexec.skills.fetch.common import (
    WORLD_ARM,
    WORLD_HELD,
    ArmSettings,
    FetchProfile,
    arm_status,
    fetch_profile,
    markers,
)
from mmexec.skills.manipulation import (
    CANCELLED,
    ArmKinematics,
    ArmModel,
    ArmPlanner,
    PlacePoses,
    PlannerConfig,
    PlanningScene,
    PlanResult,
    grasp_poses,
    place_poses,
    time_parametrize,
    ur5e,
    wx250s,
)

__all__ = ["ArmWorkspace", "arm_pose", "close_workspace", "move_named", "off_tick", "pick", "place", "workspace"]

log = logging.getLogger(__name__)

Gen = Generator[None, None, dict[str, Any]]


R = TypeVar("R")

#: [m] per side: a held item is modelled this much smaller than ``fetch.item_size``, so
#: the support it was lifted from (touching it, give or take the marker estimate's error)
#: does not count as a collision at the start of the retract.
HELD_CLEARANCE = 0.005

#: [m] release heights above the profile's place pose, tried in order: a held item that
#: sits a little off its planned hold can have no collision-free IK at the nominal height
#: (the basket wall, the robot's own body) and is then dropped from a little higher.
PLACE_RAISES = (0.0, 0.05, 0.10)


@dataclass
class ArmWorkspace:
    """Kinematics, planning scene and planner of the robot's arm (one per run, in the
    world model under ``fetch.arm``), and the one worker thread that plans.

    Ticks never wait for planning (15-300 ms, up to ``time_limit`` x ``attempts``): skills
    hand every planning-scene update and plan to :attr:`executor` (:func:`off_tick`) and
    yield until it is done. While a job runs, only the worker touches the scene's
    pybullet client. :meth:`close` (or :func:`close_workspace`, or garbage collection)
    stops a running plan, joins the worker and closes the scene's client."""

    settings: ArmSettings
    kin: ArmKinematics
    scene: PlanningScene
    planner: ArmPlanner
    executor: ThreadPoolExecutor = field(
        default_factory=lambda: ThreadPoolExecutor(max_workers=1, thread_name_prefix="arm-planner"))

    def close(self) -> None:
        """Stop a running plan, wait for the worker to finish it, free the scene."""
        self.planner.stop.set()
        self.executor.shutdown(wait=True)
        self.scene.close()

    def config(self, algorithm: str | None = None, time_limit: float | None = None,
               attempts: int | None = None) -> PlannerConfig:
        s = self.settings
        if algorithm is not None and algorithm not in ("rrtconnect", "rrtstar"):
            raise SkillFailure(FailureKind.PRECONDITION,
                               f"algorithm must be 'rrtconnect' or 'rrtstar', got {algorithm!r}")
        return PlannerConfig(algorithm=algorithm or s.algorithm, time_limit=time_limit or s.time_limit,
                             attempts=attempts or s.attempts, velocity_scale=s.velocity_scale,
                             acceleration_scale=s.acceleration_scale)


def workspace(ctx: SkillContext) -> ArmWorkspace:
    """The run's :class:`ArmWorkspace`, built from ``profile.fetch.arm`` on first use.
    PRECONDITION failure when the arm's joints differ from the planning model's."""
    ws = ctx.world.get(WORLD_ARM)
    settings = fetch_profile(ctx).arm
    if isinstance(ws, ArmWorkspace) and ws.settings == settings:
        return ws
    if isinstance(ws, ArmWorkspace):
        ws.close()
    kin = wx250s(locobot=True) if settings.model == "locobot_wx250s" else ur5e(tcp_offset=settings.tcp_offset)
    arm = ctx.robot.arm
    if arm is not None and tuple(arm.joint_names) != tuple(kin.joint_names):
        raise SkillFailure(FailureKind.PRECONDITION,
                           f"profile.fetch.arm.model {settings.model!r} plans joints {list(kin.joint_names)}, "
                           f"but the arm has {list(arm.joint_names)}")
    scene = PlanningScene(ArmModel.from_sim_model(settings.model))
    planner = ArmPlanner(scene, kin, PlannerConfig(
        algorithm=settings.algorithm, time_limit=settings.time_limit, attempts=settings.attempts,
        velocity_scale=settings.velocity_scale, acceleration_scale=settings.acceleration_scale))
    ws = ArmWorkspace(settings, kin, scene, planner)
    weakref.finalize(ws, _finalize, planner, ws.executor, scene)
    ctx.world[WORLD_ARM] = ws
    return ws


def _finalize(planner: ArmPlanner, executor: ThreadPoolExecutor, scene: PlanningScene) -> None:
    planner.stop.set()
    executor.shutdown(wait=True)
    scene.close()


def close_workspace(world: dict[str, Any]) -> None:
    """Free the planning worker and scene of a run (tests and embedding code call this at the end)."""
    ws = world.pop(WORLD_ARM, None)
    if isinstance(ws, ArmWorkspace):
        ws.close()


def off_tick(ctx: SkillContext, ws: ArmWorkspace, job: Callable[[], R]) -> Generator[None, None, R]:
    """Run ``job`` (planning-scene updates and planning) on the workspace's worker thread
    and yield once per tick until it returns, each tick waiting at most
    ``profile.fetch.arm.plan_slice`` wall seconds for it; returns its result (its
    exception is re-raised here). Cancelled: sets ``planner.stop`` so OMPL, IK and Cartesian loops end
    early, keeps yielding until the job has returned (the scene is never left to a
    running job), then re-raises.

    On a stepped clock (sim, mock: :attr:`Clock.stepped`) the first tick waits for the
    job to finish, however long it takes in wall time (the clock does not move
    meanwhile), and the result is returned one tick later: planning then costs exactly
    one tick of clock time whatever the machine's load, so a seeded run is reproducible
    to the last digit."""
    ws.planner.stop.clear()
    fut = ws.executor.submit(job)
    budget = ws.settings.plan_slice
    if getattr(ctx.clock, "stepped", False):
        while not fut.done():
            futures_wait((fut,), timeout=0.05)  # short waits: signal handlers still run
        yield  # the job has returned: a cancel here just propagates
        return fut.result()
    try:
        while True:
            # give the worker a bounded slice of this tick (well inside a tick period):
            # on the robot the runner would idle it away anyway; in sim, whose clock runs
            # many times faster than the wall clock, it keeps a 100 ms plan from costing
            # seconds of clock time. The tick never waits longer than the slice.
            futures_wait((fut,), timeout=budget)
            if fut.done():
                break
            yield
    except SkillCancelled:
        ws.planner.stop.set()
        while not fut.done():
            try:
                yield
            except SkillCancelled:
                continue
        ws.planner.stop.clear()
        raise
    return fut.result()


# --------------------------------------------------------------------------- helpers


def _T_armbase_map(ctx: SkillContext) -> np.ndarray:
    base = ctx.robot.base
    arm = ctx.robot.arm
    assert arm is not None
    T_map_base = base.state().pose.matrix() if base is not None else np.eye(4)
    return np.linalg.inv(T_map_base @ np.asarray(arm.mount, dtype=float))


def _q(ctx: SkillContext) -> list[float]:
    """Measured joint positions [rad], clamped into the joint limits: a joint resting on
    its limit reads a hair beyond it in physics (and on servos), which the planner would
    reject as a start outside the limits."""
    arm = ctx.robot.arm
    assert arm is not None
    q = [float(x) for x in arm.state().positions]
    return [min(max(x, lim.lower), lim.upper) for x, lim in zip(q, arm.limits)]


def _ik_seeds(ctx: SkillContext, ws: ArmWorkspace, T_target: np.ndarray) -> list[list[float]]:
    """IK starts for a tool pose: the profile's ``fetch.arm.reach`` posture (if any) and
    the current posture, each with the first (yaw) joint turned so the tool points at
    the target's bearing. They keep IK in the arm's natural solution family (elbow up,
    wrist not flipped) instead of whatever a random restart converges to."""
    seeds: list[list[float]] = []
    names = [n for n in (ws.settings.reach,) if n]
    postures = [_named_q(ctx, n) for n in names] + [_q(ctx)]
    bearing = math.atan2(float(T_target[1, 3]), float(T_target[0, 3]))
    lo, hi = ws.kin.limits[0].lower, ws.kin.limits[0].upper
    for q in postures:
        p = ws.kin.fk(q)[:3, 3]
        yaw = q[0] + _wrap(bearing - math.atan2(float(p[1]), float(p[0])))
        seeds.append([min(max(yaw, lo), hi), *q[1:]])
    return seeds


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _planned(ctx: SkillContext, result: PlanResult, what: str) -> PlanResult:
    if not result.success or result.trajectory is None:
        raise SkillFailure(FailureKind.PLANNING, f"{what}: {result.reason}")
    ctx.emit("arm_plan", what=what, planning_ms=round(result.planning_time * 1e3, 1), waypoints=len(result.path),
             duration=round(result.trajectory.duration, 3), attempts=result.attempts, node=ctx.node_path)
    return result


def _execute(ctx: SkillContext, result: PlanResult, what: str) -> Generator[None, None, None]:
    arm = ctx.robot.arm
    assert arm is not None and result.trajectory is not None
    goal = arm.follow(result.trajectory)
    try:
        yield from wait_goal(ctx, goal, timeout=result.trajectory.duration + 5.0)
    except SkillFailure as e:
        raise SkillFailure(e.kind, f"{what}: {e.reason}") from None


def _named_q(ctx: SkillContext, name: str) -> list[float]:
    poses = ctx.profile.get("named_poses") or {}
    q = poses.get(name) if hasattr(poses, "get") else None
    if q is None:
        raise SkillFailure(FailureKind.PRECONDITION,
                           f"no named arm pose {name!r} in the robot profile (known: {', '.join(sorted(poses)) or 'none'})")
    return [float(x) for x in q]


def move_named(ctx: SkillContext, name: str, *, cfg: PlannerConfig | None = None) -> Generator[None, None, None]:
    """Plan (against the scene) and execute a move to the profile's named arm pose.
    When the arm starts in collision with a scene item (it is touching it), the plan is
    retried without the free items."""
    ws = workspace(ctx)
    q0, q1 = _q(ctx), _named_q(ctx, name)
    if max(abs(a - b) for a, b in zip(q0, q1)) < 1e-3:
        return
    boxes, T_am = ctx.robot.scene, _T_armbase_map(ctx)
    plan_cfg = cfg or ws.config()
    res = yield from off_tick(ctx, ws, lambda: _plan_named(ws, boxes, T_am, q0, q1, name, plan_cfg))
    _planned(ctx, res, f"arm to {name}")
    yield from _execute(ctx, res, f"arm to {name}")


def _plan_named(ws: ArmWorkspace, boxes: Sequence[Any], T_am: np.ndarray, q0: list[float], q1: list[float],
                name: str, cfg: PlannerConfig) -> PlanResult:
    """(worker thread) The plan of :func:`move_named`."""
    ws.scene.set_static_boxes(boxes, T_am)
    res = ws.planner.plan(q0, q1, cfg)
    if not res.success and res.reason.startswith("start in collision"):
        for it in [n for n, item in ws.scene.items.items() if not item.attached]:
            ws.scene.remove_item(it)
        res = ws.planner.plan(q0, q1, cfg)
    if not res.success and res.reason.startswith("start in collision") and ws.scene.is_valid(q1):
        pairs = ws.scene.collisions(q0)
        if pairs and all(a.startswith("robot/") and b.startswith("robot/") for a, b in pairs):
            # The arm rests in a pose the planning model counts as self-contact (the
            # vendor's sleep pose touches the camera tower in the model): leave it along
            # the straight joint-space line, which only the arm's own links are near.
            log.info("arm starts in self-contact (%s); direct joint move to %s", pairs[0], name)
            traj = time_parametrize(ws.kin.joint_names, [tuple(q0), tuple(q1)], ws.kin.limits,
                                    velocity_scale=cfg.velocity_scale, acceleration_scale=cfg.acceleration_scale,
                                    sample_period=cfg.sample_period)
            res = PlanResult(True, "", 0.0, [tuple(q0), tuple(q1)], traj, 0)
    return res


def _item_pose_and_size(prof: FetchProfile, T_marker: np.ndarray) -> tuple[np.ndarray, tuple[float, float, float]]:
    """Box centre pose (marker axes) and size along the marker's x, y, z for an item
    whose marker is on its +x face: the box lies behind the face (along -z)."""
    sx, sy, sz = prof.item_size
    off = np.eye(4)
    off[2, 3] = -sx / 2.0
    return T_marker @ off, (sy, sz, sx)


def _holding(ctx: SkillContext, min_width: float) -> tuple[bool, str]:
    g = ctx.robot.gripper
    assert g is not None
    st = g.state()
    if st.grasp is GraspState.CONTACT_CLOSING and st.width >= min_width:
        return True, ""
    return False, f"gripper {st.grasp.value} at {st.width * 1e3:.0f} mm"


def _gripper(ctx: SkillContext, width: float | None, force: float) -> Generator[None, None, None]:
    g = ctx.robot.gripper
    assert g is not None
    goal = g.open(force=force) if width is None else g.move(width, force=force)
    yield from wait_goal(ctx, goal, timeout=10.0)


def _status_wrap(ctx: SkillContext, body: Gen, what: str) -> Gen:
    """Emit running/success/fail/idle around an arm routine."""
    arm_status(ctx, "running", action=what)
    try:
        out = yield from body
    except SkillFailure as e:
        arm_status(ctx, "fail", action=what, reason=e.reason, kind=e.kind.value)
        arm_status(ctx, "idle")
        raise
    except SkillCancelled:
        arm_status(ctx, "idle")
        raise
    arm_status(ctx, "success", action=what)
    arm_status(ctx, "idle")
    return out


# --------------------------------------------------------------------------- skills


def _planner_params() -> list[Param]:
    return [
        Param("algorithm", str, doc="OMPL planner: 'rrtconnect' or 'rrtstar' (default: profile)"),
        Param("time_limit", float, unit="s", doc="planning time per attempt (default: profile)"),
        Param("attempts", int, doc="planning attempts (default: profile)"),
    ]


@skill(
    "pick",
    params=[Param("marker", int, required=True, doc="marker id of the item (its estimate is in the world model)"),
            *_planner_params()],
    outputs=[Output("item", str, doc="planning-scene name of the held item")],
    needs=("arm", "gripper"),
)
def pick(ctx: SkillContext, marker: int, algorithm: str | None = None, time_limit: float | None = None,
         attempts: int | None = None) -> Gen:
    """Seed pick routine in the marker frame: add the item to the planning scene; plan to
    the pre-grasp (profile fetch.pre_grasp, default (0, 0, 0.10) m); open; straight in to
    the grasp (marker face, grasp_depth behind it, fingers horizontal); close; attach the
    item; straight out to the retract pose; carry pose. POSTCONDITION "nothing held"
    when the gripper closed on nothing."""
    return (yield from _status_wrap(ctx, _pick(ctx, marker, algorithm, time_limit, attempts), f"pick marker {marker}"))


def _pick(ctx: SkillContext, marker: int, algorithm: str | None, time_limit: float | None,
          attempts: int | None) -> Gen:
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
            yield from _gripper(ctx, None, fetch_profile(ctx).grasp_force)
        raise


def _pick_steps(ctx: SkillContext, marker: int, algorithm: str | None, time_limit: float | None,
                attempts: int | None) -> Gen:
    prof = fetch_profile(ctx)
    est = markers(ctx).get(marker)
    if est is None:
        raise SkillFailure(FailureKind.PRECONDITION, f"pick: no estimate of marker {marker} (detect it first)")
    ws = workspace(ctx)
    cfg = ws.config(algorithm, time_limit, attempts)
    T_am = _T_armbase_map(ctx)
    T_am_marker = T_am @ est.T_map_marker
    name = f"item_{marker}"
    T_item, size = _item_pose_and_size(prof, T_am_marker)
    poses = grasp_poses(T_am_marker, ws.kin.approach_axis, pre_grasp=prof.pre_grasp, grasp_depth=prof.grasp_depth,
                        retract=prof.retract, grasp_height=prof.grasp_height)
    q, seeds, boxes = _q(ctx), _ik_seeds(ctx, ws, poses.pre_grasp), ctx.robot.scene

    def plan_pre_grasp() -> PlanResult:
        ws.scene.set_static_boxes(boxes, T_am)
        for old in list(ws.scene.items):
            ws.scene.remove_item(old)
        ws.scene.add_item(name, size, T_item)
        return ws.planner.plan_to_pose(q, poses.pre_grasp, ik_seeds=seeds, config=cfg)

    g = ctx.robot.gripper
    assert g is not None
    opening = g.open(force=prof.grasp_force)  # opens while the plan is computed
    res = yield from off_tick(ctx, ws, plan_pre_grasp)
    ctx.emit("scene_update", op="add", item=name, node=ctx.node_path)
    pre = _planned(ctx, res, "pre-grasp")
    yield from wait_goal(ctx, opening, timeout=10.0)
    yield from _execute(ctx, pre, "pre-grasp")
    q = _q(ctx)

    def plan_approach() -> PlanResult:
        # the fingers must touch the item: take it out of the scene for the straight approach
        ws.scene.remove_item(name)
        return ws.planner.cartesian_path(q, poses.grasp, config=cfg)

    grasp = _planned(ctx, (yield from off_tick(ctx, ws, plan_approach)), "grasp approach")
    yield from _execute(ctx, grasp, "grasp approach")
    yield from wait_goal(ctx, g.close(force=prof.grasp_force), timeout=10.0)
    held, why = _holding(ctx, prof.min_held_width)
    if not held:
        yield from _gripper(ctx, None, prof.grasp_force)
        raise SkillFailure(FailureKind.POSTCONDITION, f"nothing held after closing on marker {marker} ({why})")
    q_grasp = _q(ctx)

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
    out = _planned(ctx, line, "retract")
    yield from _execute(ctx, out, "retract")
    if ctx.robot.base is not None:
        # leave the shelf before folding the arm: the carry pose sticks out in front
        from mmexec.skills.fetch.navigate import back_off

        yield from back_off(ctx, prof.back_off)
    yield from move_named(ctx, prof.arm.carry, cfg=cfg)
    held, why = _holding(ctx, prof.min_held_width)
    if not held:
        raise SkillFailure(FailureKind.POSTCONDITION, f"item of marker {marker} lost after lifting it ({why})")
    return {"item": name}


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


@skill("place", params=_planner_params(), outputs=[Output("item", str, doc="the item released")],
       needs=("arm", "gripper"))
def place(ctx: SkillContext, algorithm: str | None = None, time_limit: float | None = None,
          attempts: int | None = None) -> Gen:
    """Seed place routine at the depot (the base must be at the depot pose): plan to the
    place pose (profile fetch.depot.place, the item's centre); open; detach and remove
    the item from the planning scene; retract (profile fetch.place_retract, default
    (0, 0, 0.10) m in the place frame); close; stow the arm."""
    return (yield from _status_wrap(ctx, _place(ctx, algorithm, time_limit, attempts), "place"))


def _place(ctx: SkillContext, algorithm: str | None, time_limit: float | None, attempts: int | None) -> Gen:
    prof = fetch_profile(ctx)
    held, why = _holding(ctx, prof.min_held_width)
    if not held:
        raise SkillFailure(FailureKind.PRECONDITION, f"place: nothing held ({why})")
    ws = workspace(ctx)
    cfg = ws.config(algorithm, time_limit, attempts)
    T_am = _T_armbase_map(ctx)
    name = str(ctx.world.get(WORLD_HELD, "item"))
    base = ctx.robot.base
    bp = base.state().pose if base is not None else None
    T_map_place = _place_frame(prof.depot.place, (bp.x, bp.y) if bp is not None else (0.0, 0.0))
    # the nominal release height first; when the held item (not always held exactly as
    # planned) has no collision-free IK there, release it a little higher above the basket
    candidates: list[tuple[float, PlacePoses]] = []
    for raise_by in PLACE_RAISES:
        T = T_map_place.copy()
        T[2, 3] += raise_by
        candidates.append((raise_by, place_poses(T_am @ T, ws.kin.approach_axis, retract=prof.place_retract,
                                                 grasp_height=prof.grasp_height)))
    q, seeds, boxes = _q(ctx), _ik_seeds(ctx, ws, candidates[0][1].place), ctx.robot.scene
    chosen: list[tuple[float, PlacePoses]] = []

    def plan_place() -> PlanResult:
        ws.scene.set_static_boxes(boxes, T_am)
        res = None
        for cand in candidates:
            res = ws.planner.plan_to_pose(q, cand[1].place, ik_seeds=seeds, config=cfg)
            if res.success:
                chosen.append(cand)
                break
            if res.reason == CANCELLED:
                break
        assert res is not None
        return res

    res = _planned(ctx, (yield from off_tick(ctx, ws, plan_place)), "place pose")
    raised, poses = chosen[0]
    if raised > 0:
        ctx.emit("place_raised", by=raised, node=ctx.node_path)
    yield from _execute(ctx, res, "place pose")
    yield from _gripper(ctx, None, prof.grasp_force)
    q = _q(ctx)

    def plan_back() -> PlanResult:
        if name in ws.scene.items:
            ws.scene.detach_item(name, q)
            ws.scene.remove_item(name)
        return ws.planner.cartesian_path(q, poses.retract, config=cfg)

    ctx.world.pop(WORLD_HELD, None)
    back = yield from off_tick(ctx, ws, plan_back)
    ctx.emit("scene_update", op="detach_remove", item=name, node=ctx.node_path)
    back = _planned(ctx, back, "place retract")
    yield from _execute(ctx, back, "place retract")
    g = ctx.robot.gripper
    assert g is not None
    yield from wait_goal(ctx, g.close(force=prof.grasp_force), timeout=10.0)
    yield from move_named(ctx, prof.arm.stow, cfg=cfg)
    return {"item": name}


@skill(
    "arm_pose",
    params=[
        Param("pose", str, doc="named pose from the profile's named_poses (instead of 'role')"),
        Param("role", str, default="stow", choices=("stow", "carry", "look"),
              doc="the profile's fetch.arm pose for this role; 'look' falls back to 'stow' when the "
                  "camera is not on the arm"),
        *_planner_params(),
    ],
    needs=("arm",),
)
def arm_pose(ctx: SkillContext, pose: str | None = None, role: str = "stow", algorithm: str | None = None,
             time_limit: float | None = None, attempts: int | None = None) -> Gen:
    """Move the arm to a named pose along a collision-free planned path (the static
    scene and any perceived items): stow it before the base moves, or point an
    arm-mounted camera forward before a search."""
    prof = fetch_profile(ctx)
    if pose is not None:
        target = pose
    elif role == "look":
        target = prof.arm.look or prof.arm.stow
    else:
        target = prof.arm.carry if role == "carry" else prof.arm.stow
    ws = workspace(ctx)
    return (yield from _status_wrap(ctx, _arm_pose(ctx, target, ws.config(algorithm, time_limit, attempts)),
                                    f"arm to {target}"))


def _arm_pose(ctx: SkillContext, target: str, cfg: PlannerConfig) -> Gen:
    yield from move_named(ctx, target, cfg=cfg)
    return {}
