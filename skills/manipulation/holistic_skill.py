"""The ``holistic_standoff`` skill: where the marker-normal (or front) stand-off has no free
pose (a shelf with something in front of it, a corner), let the holistic planner find
where the base must stand, drive there, and re-plan the arm from where the base stopped.

Steps (the paper's IV-C pipeline, steps 3 to 5):

1. plan the 9-D robot (base x, y, yaw + the arm) from the current base pose to the
   pre-grasp (:class:`~mmexec.skills.manipulation.holistic.HolisticPlanner` on the arm
   workspace's worker thread, so no tick waits for it; event ``holistic_plan``);
2. stow the arm if it is not (the base drives with the arm in ``profile.arm.stow``) and
   drive to the planned base pose (:func:`~mmexec.skills.navigation.navigate.drive_path`:
   A* on the inflated map, or the local planner; ``base_status`` events);
3. re-plan the arm (RRT-Connect, ``profile.arm`` planner settings) from the base pose
   actually reached to the pre-grasp (:func:`~mmexec.skills.manipulation.holistic.replan_arm`);
   when that fails (the base stopped farther off than the plan's tolerance), plan the
   holistic problem once more from there and drive the short way again;
4. move the arm to the pre-grasp (``move_arm``, default true), so a pick routine goes on
   with the straight approach to the grasp.

Settings: the profile's ``holistic:`` section (:class:`HolisticSettings`); the arm's
planner, stow and reach postures from ``arm:``; the map inflation from ``nav:``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator, Sequence
from dataclasses import dataclass
from typing import Any, Literal

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
)
from mmexec.skills.manipulation.arm import (
    ArmWorkspace,
    arm_settings,
    execute,
    measured_joints,
    move_named,
    off_tick,
    planned,
    planner_params,
    with_arm_status,
    workspace,
)
from mmexec.skills.manipulation.grasp import grasp_poses
from mmexec.skills.manipulation.holistic import (
    HolisticConfig,
    HolisticModel,
    HolisticPlanner,
    HolisticResult,
    armbase_in_map,
    replan_arm,
)
from mmexec.skills.manipulation.planner import PlanResult
from mmexec.skills.navigation.navigate import costmap, drive_path, nav_settings, rotate_by
from mmexec.skills.poses import arm_joints
from mmexec.skills.profile import declare_settings, setting

__all__ = ["WORLD_HOLISTIC_ARM", "HolisticArm", "HolisticSettings", "grasp_frame", "holistic_seed", "holistic_settings",
           "holistic_standoff"]

log = logging.getLogger(__name__)

#: name of the target object's box in the planning scene while this skill plans
TARGET_ITEM = "holistic_target"
#: [rad] steps at which a turn on the spot is checked for the stowed arm
TURN_STEP = 0.02
#: world-model key of the last stand-off's arm solution (:class:`HolisticArm`)
WORLD_HOLISTIC_ARM = "holistic.arm"
#: ([m], [rad]) a base this close to a :class:`HolisticArm`'s pose still uses its arm solution
SEED_POSE_TOLERANCE = (0.02, 0.02)


@dataclass(frozen=True)
class HolisticArm:
    """The arm's pre-grasp joints [rad] ``arm`` that ``holistic_standoff`` re-planned
    from the base pose ``pose`` (``map``) it reached: the solution family (the holistic
    goal's) whose straight approach to the grasp was checked, for a pick that follows
    (:func:`holistic_seed`)."""

    pose: Pose2D
    arm: tuple[float, ...]


def holistic_seed(ctx: SkillContext) -> list[float] | None:
    """The last holistic stand-off's pre-grasp joints [rad] while the base is still where
    they were planned from (within :data:`SEED_POSE_TOLERANCE`), else None: a pick seeds
    its pre-grasp IK with them first, so it stays in the family whose straight approach
    the planner checked."""
    h, base = ctx.world.get(WORLD_HOLISTIC_ARM), ctx.robot.base
    if not isinstance(h, HolisticArm) or base is None:
        return None
    p = base.state().pose
    if math.hypot(p.x - h.pose.x, p.y - h.pose.y) > SEED_POSE_TOLERANCE[0] or \
            abs(math.remainder(p.theta - h.pose.theta, math.tau)) > SEED_POSE_TOLERANCE[1]:
        return None
    return list(h.arm)


@dataclass(frozen=True)
class HolisticSettings:
    """The ``holistic:`` section of a robot profile: the holistic planner's settings
    (:class:`~mmexec.skills.manipulation.holistic.HolisticConfig`) and the pre-grasp
    distance of ``holistic_standoff``."""

    algorithm: Literal["rrtconnect", "rrtstar"] = setting("rrtconnect", doc=(
        "OMPL planner over the 9-D base + arm space (the paper: rrtstar, 5 x 15 s)"))
    time_limit: float = setting(1.0, unit="s", gt=0, doc="search time per attempt")
    attempts: int = setting(5, ge=1, doc="attempts, each with fresh goal samples")
    box: float = setting(2.5, unit="m", gt=0, doc=(
        "base x and y bounds either side of the start (widened to hold the target's surroundings)"))
    goal_count: int = setting(6, ge=1, doc="goal states (base pose + arm IK) per attempt")
    goal_candidates: int = setting(300, ge=1, doc="base poses drawn around the target per attempt for them")
    yaw_spread: float = setting(1.0472, unit="rad", ge=0, le=3.1416, doc=(
        "the arm base faces the target within this"))
    tolerance: tuple[float, float] = setting((0.03, 0.03), unit="m, rad", ge=0, doc=(
        "a goal's base pose shifted this much must still reach the pre-grasp (navigation stops near it)"))
    drive_margin: tuple[float, float] = setting((0.06, 0.06), unit="m, rad", ge=0, doc=(
        "the stowed arm must be free with the base anywhere this close to a goal's base pose (the drive's "
        "arrival error: navigation's goal and heading tolerances plus the localiser's error)"))
    pre_grasp: float = setting(0.10, unit="m", ge=0, doc="pre-grasp distance from the grasp point along the approach")
    max_grasp_jump: float = setting(1.0, unit="rad", gt=0, doc=(
        "largest joint change from the pre-grasp to the grasp's IK (a goal needs a short straight approach)"))

    def config(self, algorithm: str | None = None, time_limit: float | None = None,
               attempts: int | None = None) -> HolisticConfig:
        """The planner's config, with a skill's overrides (None: the profile's)."""
        return HolisticConfig(algorithm=algorithm or self.algorithm, time_limit=time_limit or self.time_limit,
                              attempts=attempts or self.attempts, box=self.box, goal_count=self.goal_count,
                              goal_candidates=self.goal_candidates, yaw_spread=self.yaw_spread,
                              tolerance=self.tolerance, drive_margin=self.drive_margin,
                              max_grasp_jump=self.max_grasp_jump)


holistic_settings = declare_settings("holistic", HolisticSettings, package=__name__,
                                     doc="holistic base + arm planning (holistic_standoff)")


def grasp_frame(point: Sequence[float], kind: str, yaw: float) -> np.ndarray:
    """The grasp frame (4x4, ``map``, the marker convention of
    :mod:`mmexec.skills.manipulation.grasp`: z towards where the gripper comes from, y
    the tool's up) at ``point`` [m]: ``kind`` "top": z up, the fingers' travel (x) at
    heading ``yaw`` [rad]; "front": z horizontal at heading ``yaw`` (the gripper comes
    from that side), y up."""
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    if kind == "top":
        T[:3, 0], T[:3, 1], T[:3, 2] = (c, s, 0.0), (-s, c, 0.0), (0.0, 0.0, 1.0)
    else:
        T[:3, 0], T[:3, 1], T[:3, 2] = (-s, c, 0.0), (0.0, 0.0, 1.0), (c, s, 0.0)
        T[:3, 0] = np.cross(T[:3, 1], T[:3, 2])
    T[:3, 3] = [float(v) for v in point]
    return T


def _frame_from_world(ctx: SkillContext, key: str, kind: str) -> np.ndarray:
    """A 4x4 grasp frame from world-model entry ``key``: a 4x4 (array or nested list),
    an object with ``T_map_top`` / ``T_map_front`` (a perception grasp point), or one
    holding such a grasp point as ``grasp`` (the fetch_object mission's target)."""
    if key not in ctx.world:
        raise SkillFailure(FailureKind.PRECONDITION, f"holistic_standoff: no world-model entry {key!r}")
    value = ctx.world[key]
    value = getattr(value, "grasp", value)  # a fetch target holding its grasp point
    value = getattr(value, f"T_map_{kind}", value)
    try:
        T = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        T = np.zeros(0)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise SkillFailure(FailureKind.PRECONDITION,
                           f"holistic_standoff: world-model entry {key!r} holds no 4x4 grasp frame for a {kind} grasp")
    return T


def _plan_job(ws: ArmWorkspace, model: HolisticModel, planner: HolisticPlanner, boxes: Sequence[Any],
              item: tuple[tuple[float, float, float], np.ndarray] | None, start: Pose2D, q0: list[float],
              stow: list[float], T_pre: np.ndarray, T_grasp: np.ndarray, seeds: list[list[float]],
              cfg: HolisticConfig, carry: tuple[list[float], tuple[float, float, float], float] | None) -> HolisticResult:
    """(worker thread) The holistic plan over the arm workspace's scene, left at home."""
    model.prepare(boxes, {TARGET_ITEM: item} if item is not None else None)
    try:
        return planner.plan(start, q0, T_pre, T_map_grasp=T_grasp, seeds=seeds, q_drive=stow, config=cfg,
                            q_carry=carry[0] if carry else None, carry_size=carry[1] if carry else None,
                            back_off=carry[2] if carry else 0.0)
    finally:
        model.release()


def _arm_job(ws: ArmWorkspace, reached: Pose2D, mount: Sequence[float], q: list[float], T_pre: np.ndarray,
             boxes: Sequence[Any], item: tuple[tuple[float, float, float], np.ndarray] | None,
             seeds: list[list[float]], stow: list[float]) -> PlanResult:
    """(worker thread) The arm re-planned from the base pose reached, the target's box in
    the scene meanwhile; a start a few mrad off the stow posture and in collision escapes
    to it (:func:`replan_arm`)."""
    scene = ws.scene
    for name in [n for n, it in scene.items.items() if not it.attached]:
        scene.remove_item(name)
    if item is not None:
        scene.add_item(TARGET_ITEM, item[0], np.linalg.inv(armbase_in_map(reached, mount)) @ item[1])
    try:
        return replan_arm(ws.planner, reached, mount, q, T_pre, boxes, seeds=seeds, config=ws.config(), q_escape=stow)
    finally:
        if TARGET_ITEM in scene.items:
            scene.remove_item(TARGET_ITEM)


def _turn_job(model: HolisticModel, boxes: Sequence[Any], item: tuple[tuple[float, float, float], np.ndarray] | None,
              reached: Pose2D, turn: float, stow: list[float]) -> bool:
    """(worker thread) Whether the stowed arm stays clear while the base turns on the spot
    from ``reached`` by ``turn`` [rad] (checked every 0.02 rad, the end included)."""
    model.prepare(boxes, {TARGET_ITEM: item} if item is not None else None)
    try:
        n = max(1, math.ceil(abs(turn) / TURN_STEP))
        return all(model.arm_valid(reached.x, reached.y, reached.theta + turn * k / n, stow) for k in range(1, n + 1))
    finally:
        model.release()


def _align(ctx: SkillContext, ws: ArmWorkspace, model: HolisticModel, boxes: Sequence[Any],
           item: tuple[tuple[float, float, float], np.ndarray] | None, reached: Pose2D, planned: Pose2D,
           stow: list[float]) -> Generator[None, None, Pose2D]:
    """Turn the base on the spot to the plan's heading when it stopped off by more than
    navigation's heading tolerance (the drive can overshoot a turn it arrives in) and the
    stowed arm stays clear on the way; the pose then."""
    turn = math.remainder(planned.theta - reached.theta, math.tau)
    if abs(turn) <= nav_settings(ctx).heading_tolerance:
        return reached
    clear = yield from off_tick(ctx, ws, lambda: _turn_job(model, boxes, item, reached, turn, stow))
    ctx.emit("holistic_align", turn=round(turn, 3), clear=clear, node=ctx.node_path)
    if not clear:
        log.info("holistic_standoff: %.3f rad off the planned heading; the stowed arm would not clear a turn", turn)
        return reached
    yield from rotate_by(ctx, turn)
    base = ctx.robot.base
    assert base is not None
    return base.state().pose


def _emit_plan(ctx: SkillContext, res: HolisticResult, round_: int) -> None:
    pose = res.base_pose
    ctx.emit("holistic_plan", success=res.success, reason=res.reason, planning_ms=round(res.planning_time * 1e3, 1),
             attempts=res.attempts, goals=res.goals, checks=res.checks, round=round_, tolerant=res.tolerant,
             pose=[round(pose.x, 3), round(pose.y, 3), round(pose.theta, 3)] if pose is not None else None,
             arm=[round(v, 4) for v in res.arm] if res.arm is not None else None, node=ctx.node_path)


@skill(
    "holistic_standoff",
    params=[
        Param("point", list, unit="m", doc="grasp point [x, y, z] in map (the object's centre); or 'frame'"),
        Param("grasp", str, default="top", choices=("top", "front"),
              doc="top: pre-grasp above the point, approach straight down; front: horizontal approach"),
        Param("yaw", float, unit="rad", doc=(
            "top: heading of the fingers' travel in map (default 0); front: heading of the side the gripper "
            "comes from (default: from the point towards the robot)")),
        Param("frame", str, doc=(
            "world-model key of the grasp frame instead of point/yaw: a 4x4 in map, an object with "
            "T_map_top / T_map_front (a perception grasp point) or holding one as 'grasp' (fetch_object.target)")),
        Param("size", list, unit="m", doc="the object's box [x, y, z] (axes of the grasp frame), kept clear of"),
        Param("object_size", list, unit="m", doc=(
            "the object's size [length, width, height] (the catalogue's, z up): held in the profile's arm.carry "
            "posture, it must clear everything at the goal too")),
        Param("back_off", float, default=0.0, unit="m", doc=(
            "how far the pick that follows backs off before the carry posture (object_size's check is made there)")),
        Param("move_arm", bool, default=True, doc="move the arm to the pre-grasp at the end"),
        Param("timeout", float, unit="s", doc="navigation timeout (default: profile nav.timeout)"),
        Param("enabled", bool, default=True, doc=(
            "false: fail at once (PLANNING), as a mission without the holistic planner would (comparisons)")),
        *planner_params(),
    ],
    outputs=[
        Output("pose", list, doc="[x, y, theta] the base reached, map frame [m, m, rad]"),
        Output("planned", list, doc="[x, y, theta] the holistic plan's base pose, map frame"),
        Output("arm", list, doc="arm joints [rad] at the pre-grasp, re-planned from the pose reached"),
        Output("planning_ms", float, doc="holistic planning time of the last round [wall ms]"),
    ],
    needs=("base", "arm"),
)
def holistic_standoff(ctx: SkillContext, point: list | None = None, grasp: str = "top", yaw: float | None = None,
                      frame: str | None = None, size: list | None = None, move_arm: bool = True,
                      timeout: float | None = None, algorithm: str | None = None, time_limit: float | None = None,
                      attempts: int | None = None, enabled: bool = True, object_size: list | None = None,
                      back_off: float = 0.0) -> SkillGen:
    """Find where the base must stand to reach the pre-grasp of a grasp point with the
    holistic base + arm planner (the paper's three virtual joints and RRT*/RRT-Connect
    over the 9-D space), drive there with the arm stowed, re-plan the arm from the pose
    reached and (``move_arm``) move it to the pre-grasp. For targets whose front
    stand-off is blocked. The pre-grasp lies ``profile.holistic.pre_grasp`` from the
    grasp point along the approach. PLANNING when no base pose reaches it ("no base pose
    within reach ...", with the counts at each filter) or no plan is found; PRECONDITION
    for a missing or malformed target; EXECUTION when the base or the arm fails to move.
    Outputs the pose reached and planned, the arm's pre-grasp joints, the planning time.
    ``enabled`` false: PLANNING "holistic planner off" at once."""
    if not enabled:
        raise SkillFailure(FailureKind.PLANNING, "holistic planner off (enabled: false)")
    return (yield from with_arm_status(
        ctx, _holistic_standoff(ctx, point, grasp, yaw, frame, size, move_arm, timeout, algorithm, time_limit,
                                attempts, object_size, back_off), "holistic stand-off"))


def _target(ctx: SkillContext, point: list | None, grasp: str, yaw: float | None, frame: str | None) -> np.ndarray:
    if frame is not None:
        if point is not None or yaw is not None:
            raise SkillFailure(FailureKind.PRECONDITION, "holistic_standoff: give either 'frame' or point/yaw, not both")
        return _frame_from_world(ctx, frame, grasp)
    if point is None or len(point) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in point):
        raise SkillFailure(FailureKind.PRECONDITION,
                           f"holistic_standoff: 'point' must be [x, y, z] in map (m), got {point!r}")
    if yaw is None:
        if grasp == "top":
            yaw = 0.0
        else:
            base = ctx.robot.base
            assert base is not None
            p = base.state().pose
            yaw = math.atan2(p.y - point[1], p.x - point[0])
    return grasp_frame(point, grasp, yaw)


def _holistic_standoff(ctx: SkillContext, point: list | None, grasp: str, yaw: float | None, frame: str | None,
                       size: list | None, move_arm: bool, timeout: float | None, algorithm: str | None,
                       time_limit: float | None, attempts: int | None,
                       object_size: list | None = None, back_off: float = 0.0) -> Generator[None, None, dict[str, Any]]:
    T_grasp_frame = _target(ctx, point, grasp, yaw, frame)
    ctx.world.pop(WORLD_HOLISTIC_ARM, None)
    item = None
    if size is not None:
        if len(size) != 3 or not all(isinstance(v, (int, float)) and v > 0 for v in size):
            raise SkillFailure(FailureKind.PRECONDITION, f"holistic_standoff: 'size' must be 3 lengths > 0 m, got {size!r}")
        item = (tuple(float(v) for v in size), T_grasp_frame)
    carry = None
    if object_size is not None:
        if len(object_size) != 3 or not all(isinstance(v, (int, float)) and v > 0 for v in object_size):
            raise SkillFailure(FailureKind.PRECONDITION,
                               f"holistic_standoff: 'object_size' must be 3 lengths > 0 m, got {object_size!r}")
        w, h = float(max(object_size[0], object_size[1])), float(object_size[2])
        # the grasp frame's up axis: z for a top grasp, y for a front grasp
        carry_box = (w, w, h) if grasp == "top" else (w, h, w)
    settings, arm = holistic_settings(ctx), arm_settings(ctx)
    if object_size is not None and arm.carry:
        carry = (arm_joints(ctx.profile, arm.carry, "holistic_standoff"), carry_box, max(0.0, back_off))
    cfg = settings.config(algorithm, time_limit, attempts)
    ws = workspace(ctx)
    description = ctx.robot.description
    if description is None:
        raise SkillFailure(FailureKind.PRECONDITION, "holistic_standoff needs the robot's description (robot.description)")
    base = ctx.robot.base
    assert base is not None
    poses = grasp_poses(T_grasp_frame, ws.kin.approach_axis, pre_grasp=(0.0, 0.0, settings.pre_grasp))
    stow = arm_joints(ctx.profile, arm.stow, "holistic_standoff")
    seeds = [arm_joints(ctx.profile, n) for n in (arm.reach,) if n]
    boxes = ctx.robot.scene
    limit = timeout if timeout is not None else nav_settings(ctx).timeout
    assert ctx.robot.arm is not None
    mount = [float(v) for v in np.asarray(ctx.robot.arm.mount)[:3, 3]]  # T_base_armbase, as the arm skills use it
    model = HolisticModel(description, ws.kin, ws.scene, costmap(ctx), mount=mount)
    planner = HolisticPlanner(model, cfg)
    planner.stop = ws.planner.stop  # one cancel flag for every plan of the workspace (off_tick sets it)
    planned_pose: Pose2D | None = None
    res: HolisticResult | None = None
    for round_ in range(2):
        start, q0 = base.state().pose, measured_joints(ctx)
        res = yield from off_tick(ctx, ws, lambda s=start, q=q0: _plan_job(
            ws, model, planner, boxes, item, s, q, stow, poses.pre_grasp, poses.grasp, seeds, cfg, carry))
        _emit_plan(ctx, res, round_)
        if not res.success or res.base_pose is None or res.arm is None:
            raise SkillFailure(FailureKind.PLANNING, f"holistic plan: {res.reason}")
        planned_pose = res.base_pose
        if max(abs(a - b) for a, b in zip(measured_joints(ctx), stow)) > 1e-3:
            yield from move_named(ctx, arm.stow)
        reached = yield from drive_path(ctx, planned_pose, "holistic stand-off", timeout=limit)
        reached = yield from _align(ctx, ws, model, boxes, item, reached, planned_pose, stow)
        q = measured_joints(ctx)
        arm_plan = yield from off_tick(ctx, ws, lambda r=reached, qq=q, goal=res.arm: _arm_job(
            ws, r, mount, qq, poses.pre_grasp, boxes, item, [list(goal), *seeds], stow))
        if arm_plan.success:
            break
        log.info("holistic_standoff: arm re-plan from (%.2f, %.2f, %.2f) failed (%s)%s", reached.x, reached.y,
                 reached.theta, arm_plan.reason, "; planning again from there" if round_ == 0 else "")
        ctx.emit("holistic_arm_replan", success=False, reason=arm_plan.reason, round=round_,
                 reached=[round(reached.x, 3), round(reached.y, 3), round(reached.theta, 3)], node=ctx.node_path)
    out = planned(ctx, arm_plan, "pre-grasp from the holistic stand-off")
    if move_arm:
        yield from execute(ctx, out, "pre-grasp from the holistic stand-off")
    assert planned_pose is not None and res is not None
    final = base.state().pose
    ctx.world[WORLD_HOLISTIC_ARM] = HolisticArm(final, tuple(float(v) for v in out.path[-1]))
    return {"pose": [final.x, final.y, final.theta], "planned": [planned_pose.x, planned_pose.y, planned_pose.theta],
            "arm": [float(v) for v in out.path[-1]], "planning_ms": round(res.planning_time * 1e3, 1)}
