"""Arm motion skills: every motion planned (IK + OMPL, RRTConnect by default, RRT*
selectable) against a planning scene made of the robot's static boxes (``robot.scene``)
plus the items skills add, on a worker thread so no tick waits for it, and executed with
``robot.arm.follow(trajectory)``.

Skill: ``arm_pose`` (a named pose, or the pose of a role: stow, carry, look). The pieces
other arm skills are built from (the fetch package's ``pick`` and ``place``): the run's
:class:`ArmWorkspace` (:func:`workspace`), :func:`off_tick` (plan without blocking a
tick), :func:`planned` / :func:`execute`, :func:`move_named`, :func:`ik_seeds`, the
gripper checks :func:`holding` and :func:`release`, and :func:`with_arm_status`, which
emits the seed's arm states as ``arm_status`` events: ``running``, ``success``, ``fail``
(with the reason) and ``idle``.

Settings: the profile's ``arm:`` section (:class:`ArmSettings`: planner, speed scaling,
the named poses of each role, the gripper's force and closed width). The kinematics and
collision model are the robot's description (``robot.description``,
:mod:`mmexec.drivers.descriptions`).
World model: the workspace under ``arm.workspace``, the name of the item the robot
believes it holds under ``arm.held``.

Frames: tool poses are computed in ``map``, then moved into the arm base frame through
the base pose (odometry) and the arm mount: ``T_armbase_map = inv(T_map_base @
T_base_armbase)``.
"""

from __future__ import annotations

import logging
import math
import weakref
from collections.abc import Callable, Generator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from dataclasses import dataclass, field
from typing import Any, Literal, TypeVar

import numpy as np

from mmexec.config.yamlload import did_you_mean
from mmexec.drivers.descriptions import RobotDescription, get, names
from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import GraspState
from mmexec.skills.base import (
    FailureKind,
    Param,
    SkillCancelled,
    SkillContext,
    SkillFailure,
    SkillGen,
    skill,
    wait_goal,
)
from mmexec.skills.manipulation import (
    ArmKinematics,
    ArmModel,
    ArmPlanner,
    PlannerConfig,
    PlanningScene,
    PlanResult,
    time_parametrize,
)
from mmexec.skills.poses import arm_joints
from mmexec.skills.profile import declare_settings, setting

__all__ = [
    "WORLD_ARM",
    "WORLD_HELD",
    "ArmSettings",
    "ArmWorkspace",
    "T_armbase_map",
    "arm_pose",
    "arm_settings",
    "arm_status",
    "close_workspace",
    "execute",
    "holding",
    "ik_seeds",
    "measured_joints",
    "move_named",
    "off_tick",
    "planned",
    "planner_params",
    "release",
    "role_pose",
    "with_arm_status",
    "workspace",
]

log = logging.getLogger(__name__)

R = TypeVar("R")

WORLD_ARM = "arm.workspace"
WORLD_HELD = "arm.held"

#: Longest a gripper move may take [clock s].
GRIPPER_TIMEOUT = 10.0


# --------------------------------------------------------------------------- profile


@dataclass(frozen=True)
class ArmSettings:
    """The ``arm:`` section of a robot profile: the robot model it is written for, the
    grasp point, the OMPL planner's settings, speed scaling, the named poses (keys of the profile's ``named_poses``) the
    skills use in each role, and the gripper's force and closed width. Planning runs on a
    worker thread; on a wall clock each tick waits at most ``plan_slice`` [wall s] for it
    (keep it well below the tick period), then yields; on a stepped clock (sim, mock) the
    tick waits for the plan, which costs exactly one tick of clock time."""

    model: str | None = setting(None, doc=(
        "the robot model (mmexec.drivers.descriptions) this profile is written for: the robot's "
        "description must be this one; planned with when the backend names none (None: any)"))
    tcp_offset: float | None = setting(None, unit="m", ge=0, doc=(
        "tool link to the grasp point along the approach axis (None: the robot description's: "
        "0 on the LoCoBot, 0.155 on the UR5e + 2F-85)"))
    algorithm: Literal["rrtconnect", "rrtstar"] = setting("rrtconnect", doc="OMPL planner")
    time_limit: float = setting(1.0, unit="s", gt=0, doc="planning time per attempt")
    attempts: int = setting(3, ge=1, doc="planning attempts")
    velocity_scale: float = setting(0.8, gt=0, le=1, doc="fraction of the joint velocity limits")
    acceleration_scale: float = setting(0.8, gt=0, le=1, doc="fraction of the joint acceleration limits")
    stow: str = setting("sleep", refers_to="named_poses", doc="named pose to stow the arm in while driving")
    carry: str = setting("sleep", refers_to="named_poses", doc="named pose to carry an item in")
    look: str | None = setting(None, refers_to="named_poses",
                               doc="named pose to look with an arm-mounted camera (None: camera not on the arm)")
    reach: str | None = setting(None, refers_to="named_poses", doc=(
        "posture that seeds IK for pick and place poses, its yaw joint turned towards the target "
        "(None: the current posture only)"))
    plan_slice: float = setting(0.015, unit="wall s", ge=0, le=0.1, doc="longest a tick waits for the planner on a wall clock")
    grasp_force: float = setting(20.0, unit="N", gt=0, doc="gripper force")
    min_held_width: float = setting(0.01, unit="m", ge=0, doc="a closed gripper narrower than this holds nothing")

    def validate(self) -> list[str]:
        """``model`` names a registered robot description."""
        if self.model is None or self.model in names():
            return []
        return [f"model: unknown robot model {self.model!r}" + did_you_mean(self.model, names())
                + f" (known: {', '.join(names())})"]


arm_settings = declare_settings("arm", ArmSettings, package=__name__,
                                doc="arm motion: robot model check, planner, role poses, gripper force")


def arm_status(ctx: SkillContext, status: str, **fields: Any) -> None:
    """Emit the seed's arm state: ``running``, ``success``, ``fail`` or ``idle``."""
    ctx.emit("arm_status", status=status, node=ctx.node_path, **fields)


# --------------------------------------------------------------------------- workspace


@dataclass
class ArmWorkspace:
    """Kinematics, planning scene and planner of the robot's arm (one per run, in the
    world model under ``arm.workspace``), and the one worker thread that plans.

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
        """The planner settings of the profile, with a skill's overrides (None: the profile's)."""
        s = self.settings
        if algorithm is not None and algorithm not in ("rrtconnect", "rrtstar"):
            raise SkillFailure(FailureKind.PRECONDITION,
                               f"algorithm must be 'rrtconnect' or 'rrtstar', got {algorithm!r}")
        return PlannerConfig(algorithm=algorithm or s.algorithm, time_limit=time_limit or s.time_limit,
                             attempts=attempts or s.attempts, velocity_scale=s.velocity_scale,
                             acceleration_scale=s.acceleration_scale)


def workspace(ctx: SkillContext) -> ArmWorkspace:
    """The run's :class:`ArmWorkspace`, built on first use from the robot's description
    (kinematics, collision model) and ``profile.arm``. PRECONDITION failure when the robot
    has no description with an arm, when it is not the model ``profile.arm.model`` names,
    or when the arm's joints differ from the description's."""
    ws = ctx.world.get(WORLD_ARM)
    settings = arm_settings(ctx)
    if isinstance(ws, ArmWorkspace) and ws.settings == settings:
        return ws
    if isinstance(ws, ArmWorkspace):
        ws.close()
    description = _planning_description(ctx.robot.description, settings)
    kin = ArmKinematics.from_description(description, tcp_offset=settings.tcp_offset)
    arm = ctx.robot.arm
    if arm is not None and tuple(arm.joint_names) != tuple(kin.joint_names):
        raise SkillFailure(FailureKind.PRECONDITION,
                           f"robot model {description.name!r} plans joints {list(kin.joint_names)}, "
                           f"but the arm has {list(arm.joint_names)}")
    scene = PlanningScene(ArmModel.from_description(description))
    planner = ArmPlanner(scene, kin, PlannerConfig(
        algorithm=settings.algorithm, time_limit=settings.time_limit, attempts=settings.attempts,
        velocity_scale=settings.velocity_scale, acceleration_scale=settings.acceleration_scale))
    ws = ArmWorkspace(settings, kin, scene, planner)
    weakref.finalize(ws, _finalize, planner, ws.executor, scene)
    ctx.world[WORLD_ARM] = ws
    return ws


def _planning_description(description: RobotDescription | None, settings: ArmSettings) -> RobotDescription:
    """The robot's ``description`` to plan with, or the one ``settings.model`` names when
    the backend gives none (a robot config without ``robot.description``); PRECONDITION
    failure when there is neither, it has no arm, or the two are different models."""
    if description is None and settings.model is not None:
        description = get(settings.model)
    if description is None:
        raise SkillFailure(FailureKind.PRECONDITION, "the robot has no description to plan with: name its model "
                           "in the config (robot.description, sim.robot or profile.arm.model: one of "
                           f"{', '.join(names())})")
    if settings.model is not None and settings.model != description.name:
        raise SkillFailure(FailureKind.PRECONDITION, f"profile.arm.model {settings.model!r} is not this robot's "
                           f"model {description.name!r}")
    if description.arm is None:
        raise SkillFailure(FailureKind.PRECONDITION, f"robot model {description.name!r} has no arm to plan for")
    return description


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
    ``profile.arm.plan_slice`` wall seconds for it; returns its result (its exception is
    re-raised here). Cancelled: sets ``planner.stop`` so OMPL, IK and Cartesian loops end
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


def T_armbase_map(ctx: SkillContext) -> np.ndarray:
    """``inv(T_map_base @ T_base_armbase)``: map to the arm base frame, through the base's
    odometry pose (identity without a base) and the arm mount."""
    base = ctx.robot.base
    arm = ctx.robot.arm
    assert arm is not None
    T_map_base = base.state().pose.matrix() if base is not None else np.eye(4)
    return np.linalg.inv(T_map_base @ np.asarray(arm.mount, dtype=float))


def measured_joints(ctx: SkillContext) -> list[float]:
    """Measured joint positions [rad], clamped into the joint limits: a joint resting on
    its limit reads a hair beyond it in physics (and on servos), which the planner would
    reject as a start outside the limits."""
    arm = ctx.robot.arm
    assert arm is not None
    q = [float(x) for x in arm.state().positions]
    return [min(max(x, lim.lower), lim.upper) for x, lim in zip(q, arm.limits)]


def ik_seeds(ctx: SkillContext, ws: ArmWorkspace, T_target: np.ndarray) -> list[list[float]]:
    """IK starts for a tool pose (4x4, arm base frame): the profile's ``arm.reach``
    posture (if any) and the current posture, each with the first (yaw) joint turned so
    the tool points at the target's bearing. They keep IK in the arm's natural solution
    family (elbow up, wrist not flipped) instead of whatever a random restart converges to."""
    seeds: list[list[float]] = []
    names = [n for n in (ws.settings.reach,) if n]
    postures = [arm_joints(ctx.profile, n) for n in names] + [measured_joints(ctx)]
    bearing = math.atan2(float(T_target[1, 3]), float(T_target[0, 3]))
    lo, hi = ws.kin.limits[0].lower, ws.kin.limits[0].upper
    for q in postures:
        p = ws.kin.fk(q)[:3, 3]
        yaw = q[0] + wrap_angle(bearing - math.atan2(float(p[1]), float(p[0])))
        seeds.append([min(max(yaw, lo), hi), *q[1:]])
    return seeds


def planned(ctx: SkillContext, result: PlanResult, what: str) -> PlanResult:
    """``result`` when it holds a trajectory (emitting ``arm_plan``), else
    SkillFailure(PLANNING) "WHAT: reason"."""
    if not result.success or result.trajectory is None:
        raise SkillFailure(FailureKind.PLANNING, f"{what}: {result.reason}")
    ctx.emit("arm_plan", what=what, planning_ms=round(result.planning_time * 1e3, 1), waypoints=len(result.path),
             duration=round(result.trajectory.duration, 3), attempts=result.attempts, node=ctx.node_path)
    return result


def execute(ctx: SkillContext, result: PlanResult, what: str) -> Generator[None, None, None]:
    """Follow the planned trajectory, at most its duration + 5 s [clock s]; a failure's
    reason is prefixed with ``what``."""
    arm = ctx.robot.arm
    assert arm is not None and result.trajectory is not None
    goal = arm.follow(result.trajectory)
    try:
        yield from wait_goal(ctx, goal, timeout=result.trajectory.duration + 5.0)
    except SkillFailure as e:
        raise SkillFailure(e.kind, f"{what}: {e.reason}") from None


def move_named(ctx: SkillContext, name: str, *, cfg: PlannerConfig | None = None) -> Generator[None, None, None]:
    """Plan (against the scene) and execute a move to the profile's named arm pose.
    When the arm starts in collision with a scene item (it is touching it), the plan is
    retried without the free items."""
    ws = workspace(ctx)
    q0, q1 = measured_joints(ctx), arm_joints(ctx.profile, name)
    if max(abs(a - b) for a, b in zip(q0, q1)) < 1e-3:
        return
    boxes, T_am = ctx.robot.scene, T_armbase_map(ctx)
    plan_cfg = cfg or ws.config()
    res = yield from off_tick(ctx, ws, lambda: _plan_named(ws, boxes, T_am, q0, q1, name, plan_cfg))
    planned(ctx, res, f"arm to {name}")
    yield from execute(ctx, res, f"arm to {name}")


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


def holding(ctx: SkillContext, min_width: float) -> tuple[bool, str]:
    """Whether the gripper holds something (it stopped closing on contact, at least
    ``min_width`` [m] open), and if not, what it reports."""
    g = ctx.robot.gripper
    assert g is not None
    st = g.state()
    if st.grasp is GraspState.CONTACT_CLOSING and st.width >= min_width:
        return True, ""
    return False, f"gripper {st.grasp.value} at {st.width * 1e3:.0f} mm"


def release(ctx: SkillContext, force: float) -> Generator[None, None, None]:
    """Open the gripper fully with ``force`` [N], at most :data:`GRIPPER_TIMEOUT` clock s."""
    g = ctx.robot.gripper
    assert g is not None
    yield from wait_goal(ctx, g.open(force=force), timeout=GRIPPER_TIMEOUT)


def with_arm_status(ctx: SkillContext, body: SkillGen, what: str) -> SkillGen:
    """Run an arm routine, emitting ``arm_status`` running / success / fail / idle around it."""
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


def planner_params() -> list[Param]:
    """The planner parameters every planning arm skill takes (defaults: profile ``arm``)."""
    return [
        Param("algorithm", str, doc="OMPL planner: 'rrtconnect' or 'rrtstar' (default: profile)"),
        Param("time_limit", float, unit="s", doc="planning time per attempt (default: profile)"),
        Param("attempts", int, doc="planning attempts (default: profile)"),
    ]


# --------------------------------------------------------------------------- skills


def role_pose(settings: ArmSettings, role: str) -> str:
    """The named pose of ``role`` (stow, carry, look); look falls back to stow when the
    camera is not on the arm (``arm.look`` unset)."""
    roles: Mapping[str, str | None] = {"stow": settings.stow, "carry": settings.carry,
                                       "look": settings.look or settings.stow}
    target = roles[role]
    assert target is not None
    return target


@skill(
    "arm_pose",
    params=[
        Param("pose", str, doc="named pose from the profile's named_poses (instead of 'role')"),
        Param("role", str, default="stow", choices=("stow", "carry", "look"),
              doc="the profile's arm pose for this role; 'look' falls back to 'stow' when the "
                  "camera is not on the arm"),
        *planner_params(),
    ],
    needs=("arm",),
)
def arm_pose(ctx: SkillContext, pose: str | None = None, role: str = "stow", algorithm: str | None = None,
             time_limit: float | None = None, attempts: int | None = None) -> SkillGen:
    """Move the arm to a named pose along a collision-free planned path (the static
    scene and any perceived items): stow it before the base moves, or point an
    arm-mounted camera forward before a search."""
    target = pose if pose is not None else role_pose(arm_settings(ctx), role)
    ws = workspace(ctx)
    return (yield from with_arm_status(ctx, _arm_pose(ctx, target, ws.config(algorithm, time_limit, attempts)),
                                       f"arm to {target}"))


def _arm_pose(ctx: SkillContext, target: str, cfg: PlannerConfig) -> SkillGen:
    yield from move_named(ctx, target, cfg=cfg)
    return {}
