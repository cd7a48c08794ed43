"""Primitive skills: wait, report, move the arm, open / close the gripper, drive, stop;
and the base's motion loop that every skill driving the base runs (:func:`motion_loop`,
around :func:`brake`).

They talk only to the capability interfaces, never block, and are cancellable at any
tick: a cancelled arm or gripper move cancels its goal and waits for the backend to
report it stopped; a cancelled drive brakes the base and waits until it is at rest.

Importing this module registers the skills in :data:`mmexec.skills.base.REGISTRY` (the
executive's config loader and runner import it explicitly).

Robot profile keys read here (all optional):

* ``named_poses``: ``{name: [q1, ..., qn]}`` arm joint poses [rad], for ``move_arm``;
* ``home``: ``[x, y, theta]`` base pose in ``map`` [m, m, rad], for ``drive_to place=home``;
* ``places``: ``{name: [x, y, theta]}`` more named base poses in ``map``

(looked up through :mod:`mmexec.skills.poses`).
"""

from __future__ import annotations

import enum
import logging
import math
from collections.abc import Callable, Generator, Sequence

from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import BLIND_FAULTS, Base, BaseState, Pose2D
from mmexec.skills.base import (
    FailureKind,
    Output,
    Param,
    SkillCancelled,
    SkillContext,
    SkillFailure,
    SkillGen,
    skill,
    wait_goal,
)
from mmexec.skills.poses import arm_joints, base_pose

__all__ = [
    "Step",
    "brake",
    "close_gripper",
    "drive_to",
    "motion_loop",
    "move_arm",
    "open_gripper",
    "report",
    "stop_base",
    "wait",
]

log = logging.getLogger(__name__)

#: Below these speeds [m/s, rad/s] a braking base counts as stopped.
STOPPED_V = 1e-3
STOPPED_W = 1e-3
#: Longest a braking base is waited for [clock s] before the skill gives up waiting.
BRAKE_LIMIT = 3.0


def _require_finite(skill_name: str, **values: float | Sequence[float] | None) -> None:
    """Raise SkillFailure(PRECONDITION) naming the first parameter that is, or holds, a NaN
    or an infinity (None means "not given" and passes). The mission loader already
    refuses such constants; this also stops ones that arrive through the blackboard or a
    robot profile before they reach a motor (a NaN goal would drive the base forever)."""
    for name, value in values.items():
        items = value if isinstance(value, Sequence) else [value]
        for x in items:
            if isinstance(x, (int, float)) and not isinstance(x, bool) and not math.isfinite(x):
                raise SkillFailure(FailureKind.PRECONDITION, f"{skill_name}: {name} must be a finite number, got {value!r}")


# --------------------------------------------------------------------------- wait / report


@skill("wait", params=[Param("seconds", float, unit="s", required=True, doc="clock time to wait")])
def wait(ctx: SkillContext, seconds: float) -> SkillGen:
    """Succeed after ``seconds`` of clock time."""
    _require_finite("wait", seconds=seconds)
    if seconds < 0:
        raise SkillFailure(FailureKind.PRECONDITION, f"wait: seconds must be >= 0, got {seconds:g}")
    end = ctx.clock.now() + seconds
    while ctx.clock.now() < end - 1e-9:
        yield
    return {}


@skill(
    "report",
    params=[
        Param("message", str, required=True, doc="text for the event log"),
        Param("level", str, default="info", choices=("info", "warning", "error")),
    ],
)
def report(ctx: SkillContext, message: str, level: str = "info") -> SkillGen:
    """Write ``message`` to the event log (event ``report``; ``mmexec run`` also prints
    it) and, at debug level, to the Python log; succeed at once."""
    yield from ()
    ctx.emit("report", message=message, level=level, node=ctx.node_path)
    log.debug("report (%s): %s", level, message)
    return {}


# --------------------------------------------------------------------------- arm


@skill(
    "move_arm",
    params=[
        Param("pose", str, doc="named pose from the profile's named_poses"),
        Param("joints", list, unit="rad", doc="explicit joint vector, in the arm's joint order"),
        Param("speed_scale", float, default=0.5, doc="fraction (0, 1] of the joints' velocity limits"),
        Param("timeout", float, unit="s", doc="fail if the move takes longer (clock time)"),
    ],
    outputs=[Output("joints", list, doc="joint positions reached [rad]")],
    needs=("arm",),
)
def move_arm(
    ctx: SkillContext,
    pose: str | None = None,
    joints: list[float] | None = None,
    speed_scale: float = 0.5,
    timeout: float | None = None,
) -> SkillGen:
    """Move the arm in joint space to a named pose or an explicit joint vector [rad]."""
    arm = ctx.robot.arm
    assert arm is not None  # guaranteed by needs=("arm",)
    if (pose is None) == (joints is None):
        raise SkillFailure(FailureKind.PRECONDITION, "move_arm: give exactly one of 'pose' or 'joints'")
    if joints is not None:
        if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in joints):
            raise SkillFailure(FailureKind.PRECONDITION, f"move_arm: joints must be numbers, got {joints!r}")
        q = [float(x) for x in joints]
    else:
        assert pose is not None
        q = arm_joints(ctx.profile, pose, "move_arm")
    _require_finite("move_arm", joints=q, speed_scale=speed_scale, timeout=timeout)
    if len(q) != len(arm.joint_names):
        raise SkillFailure(
            FailureKind.PRECONDITION,
            f"move_arm: {len(q)} joint values for an arm with {len(arm.joint_names)} joints",
        )
    for lim, x in zip(arm.limits, q):
        if not lim.contains(x):
            raise SkillFailure(
                FailureKind.PRECONDITION,
                f"move_arm: joint {lim.name!r} target {x:.3f} rad outside [{lim.lower:.3f}, {lim.upper:.3f}]",
            )
    if not 0.0 < speed_scale <= 1.0:
        raise SkillFailure(FailureKind.PRECONDITION, f"move_arm: speed_scale {speed_scale:g} outside (0, 1]")
    goal = arm.move_to(q, speed_scale=speed_scale)
    yield from wait_goal(ctx, goal, timeout=timeout)
    return {"joints": list(arm.state().positions)}


# --------------------------------------------------------------------------- gripper


@skill(
    "open_gripper",
    params=[
        Param("width", float, unit="m", doc="opening; default fully open"),
        Param("speed", float, unit="m/s", default=0.1),
        Param("force", float, unit="N", default=50.0),
    ],
    needs=("gripper",),
)
def open_gripper(ctx: SkillContext, width: float | None = None, speed: float = 0.1, force: float = 50.0) -> SkillGen:
    """Open the gripper fully, or to ``width`` [m]."""
    gripper = ctx.robot.gripper
    assert gripper is not None
    _require_finite("open_gripper", width=width, speed=speed, force=force)
    goal = gripper.open(speed=speed, force=force) if width is None else gripper.move(width, speed=speed, force=force)
    yield from wait_goal(ctx, goal)
    return {}


@skill(
    "close_gripper",
    params=[
        Param("force", float, unit="N", default=50.0, doc="grip force"),
        Param("speed", float, unit="m/s", default=0.1),
        Param("expect", str, default="any", choices=("any", "object", "empty"),
              doc="'object': fail unless something is held; 'empty': fail if something is"),
    ],
    outputs=[Output("holding", bool, doc="whether the fingers stopped on an object")],
    needs=("gripper",),
)
def close_gripper(ctx: SkillContext, force: float = 50.0, speed: float = 0.1, expect: str = "any") -> SkillGen:
    """Close the gripper; output ``holding``. ``expect`` turns a wrong result into a
    POSTCONDITION failure."""
    gripper = ctx.robot.gripper
    assert gripper is not None
    _require_finite("close_gripper", force=force, speed=speed)
    goal = gripper.close(speed=speed, force=force)
    yield from wait_goal(ctx, goal)
    holding = gripper.state().holding
    if expect == "object" and not holding:
        raise SkillFailure(FailureKind.POSTCONDITION, "close_gripper: closed on nothing (expected an object)")
    if expect == "empty" and holding:
        raise SkillFailure(FailureKind.POSTCONDITION, "close_gripper: holding an object (expected empty)")
    return {"holding": holding}


# --------------------------------------------------------------------------- base


def brake(ctx: SkillContext, base: Base, limit: float = BRAKE_LIMIT) -> Generator[None, None, bool]:
    """Command zero velocity every tick until the base is at rest or ``limit`` clock
    seconds passed; returns True when it came to rest. Further cancellation is ignored
    (it is already braking). A base with a :data:`BLIND_FAULTS` fault gets its stop and
    the loop returns False at once: there is no measurement to wait for, and the failure
    it reports must not be delayed."""
    end = ctx.clock.now() + limit
    while True:
        base.stop()
        st = base.state()
        if st.faults & BLIND_FAULTS:
            return False
        if abs(st.v) < STOPPED_V and abs(st.w) < STOPPED_W:
            return True
        if ctx.clock.now() > end:
            log.warning("base still moving (v=%.3f m/s, w=%.3f rad/s) %.1f s after stop", st.v, st.w, limit)
            return False
        try:
            yield
        except SkillCancelled:
            continue  # already braking


class Step(enum.Enum):
    """What a :func:`motion_loop` step returns instead of a velocity command."""

    HOLD = "hold"          # send nothing this tick (the last command stands)
    ARRIVED = "arrived"    # the motion is done: brake to rest


#: ``step(state, now)`` of :func:`motion_loop`: the base's state and the clock time [s]
#: in, a command (v [m/s], w [rad/s]) or a :class:`Step` out.
MotionStep = Callable[[BaseState, float], "tuple[float, float] | Step"]


def motion_loop(ctx: SkillContext, base: Base, step: MotionStep, *, fault: str, deadline: float | None,
                timeout: str, timeout_kind: FailureKind = FailureKind.EXECUTION,
                on_failure: Callable[[str], None] | None = None) -> Generator[None, None, bool]:
    """Drive ``base`` one tick at a time, braking on every way out: fault -> brake ->
    fail, timeout -> brake -> fail, cancel -> brake, arrived -> brake.

    Each tick: read the base state; on a fault brake, call ``on_failure("base fault: F,
    G")`` and fail with EXECUTION "FAULT: F, G" (``fault`` is the message's start); past
    ``deadline`` [clock s] brake, call ``on_failure("timeout")`` and fail with
    ``timeout_kind`` and the message ``timeout``; else ``step(state, now)`` gives the
    command to send, :attr:`Step.HOLD` (none this tick) or :attr:`Step.ARRIVED`: then brake
    and return whether the base came to rest. Cancellation brakes, then re-raises."""
    try:
        while True:
            st = base.state()
            if st.faults:
                yield from brake(ctx, base)
                faults = ", ".join(sorted(st.faults))
                if on_failure is not None:
                    on_failure(f"base fault: {faults}")
                raise SkillFailure(FailureKind.EXECUTION, f"{fault}: {faults}")
            now = ctx.clock.now()
            if deadline is not None and now > deadline:
                yield from brake(ctx, base)
                if on_failure is not None:
                    on_failure("timeout")
                raise SkillFailure(timeout_kind, timeout)
            cmd = step(st, now)
            if cmd is Step.ARRIVED:
                return (yield from brake(ctx, base))
            if cmd is not Step.HOLD:
                base.set_velocity(*cmd)
            yield
    except SkillCancelled:
        yield from brake(ctx, base)
        raise


@skill(
    "drive_to",
    params=[
        Param("x", float, unit="m", doc="goal x in map"),
        Param("y", float, unit="m", doc="goal y in map"),
        Param("theta", float, unit="rad", doc="goal heading in map; default: keep the arrival heading"),
        Param("place", str, doc="named goal instead of x/y/theta: 'home' or a profile 'places' key"),
        Param("tolerance", float, unit="m", default=0.05),
        Param("angle_tolerance", float, unit="rad", default=0.05),
        Param("max_linear", float, unit="m/s", default=0.3),
        Param("max_angular", float, unit="rad/s", default=1.0),
        Param("timeout", float, unit="s", doc="fail after this much clock time"),
    ],
    outputs=[Output("pose", list, doc="[x, y, theta] reached, map frame [m, m, rad]")],
    needs=("base",),
)
def drive_to(
    ctx: SkillContext,
    x: float | None = None,
    y: float | None = None,
    theta: float | None = None,
    place: str | None = None,
    tolerance: float = 0.05,
    angle_tolerance: float = 0.05,
    max_linear: float = 0.3,
    max_angular: float = 1.0,
    timeout: float | None = None,
) -> SkillGen:
    """Drive the base straight to a pose in ``map`` (turn, drive, turn), with no obstacle
    avoidance; path planning is the navigation skill's job. A base fault (bumper, cliff,
    wheel drop) stops the base and fails with EXECUTION."""
    base = ctx.robot.base
    assert base is not None
    if place is not None:
        if x is not None or y is not None or theta is not None:
            raise SkillFailure(FailureKind.PRECONDITION, "drive_to: give either 'place' or x/y/theta, not both")
        goal = base_pose(ctx, place, "drive_to")
        gx, gy, gth = goal.x, goal.y, goal.theta
    else:
        if x is None or y is None:
            raise SkillFailure(FailureKind.PRECONDITION, "drive_to: 'x' and 'y' are required (or give 'place')")
        gx, gy, gth = x, y, theta
    _require_finite("drive_to", x=gx, y=gy, theta=gth, tolerance=tolerance, angle_tolerance=angle_tolerance,
                    max_linear=max_linear, max_angular=max_angular, timeout=timeout)
    if tolerance <= 0 or angle_tolerance <= 0 or max_linear <= 0 or max_angular <= 0:
        raise SkillFailure(FailureKind.PRECONDITION, "drive_to: tolerances and speed limits must be > 0")
    v_max = min(max_linear, base.max_linear)
    w_max = min(max_angular, base.max_angular)
    deadline = None if timeout is None else ctx.clock.now() + timeout
    k_w = 2.0
    at_position = False

    def step(st: BaseState, _now: float) -> tuple[float, float] | Step:
        """Turn towards the goal and drive to it; at the position, turn to ``theta``."""
        nonlocal at_position
        p = st.pose
        dx, dy = gx - p.x, gy - p.y
        dist = math.hypot(dx, dy)
        if at_position and dist > 2.0 * tolerance:
            at_position = False
        if not at_position and dist <= tolerance:
            at_position = True
        if not at_position:
            err = wrap_angle(math.atan2(dy, dx) - p.theta)
            w = max(-w_max, min(w_max, k_w * err))
            v = 0.0 if abs(err) > 0.35 else min(v_max, math.sqrt(2.0 * base.max_linear_accel * 0.5 * dist)) * math.cos(err)
            return v, w
        err = 0.0 if gth is None else wrap_angle(gth - p.theta)
        if abs(err) <= angle_tolerance:
            return Step.ARRIVED
        w = max(-w_max, min(w_max, k_w * err))
        return 0.0, math.copysign(max(abs(w), 0.05), w)

    while True:
        rested = yield from motion_loop(ctx, base, step, fault="drive_to: base fault", deadline=deadline,
                                        timeout=f"drive_to: not there after {timeout or 0:g} s",
                                        timeout_kind=FailureKind.TIMEOUT)
        if not rested:
            raise SkillFailure(FailureKind.EXECUTION, "drive_to: the base did not come to rest")
        st = base.state()
        if st.pose.distance_to(Pose2D(gx, gy)) <= 2.0 * tolerance:
            return {"pose": [st.pose.x, st.pose.y, st.pose.theta]}
        at_position = False  # pushed off the goal while braking: drive back to it


@skill("stop_base", needs=("base",), outputs=[Output("pose", list, doc="[x, y, theta] at rest, map frame")])
def stop_base(ctx: SkillContext) -> SkillGen:
    """Brake the base to rest; fails if it is still moving after a few seconds."""
    base = ctx.robot.base
    assert base is not None
    rested = yield from brake(ctx, base)
    if not rested:
        raise SkillFailure(FailureKind.EXECUTION, "stop_base: the base did not come to rest")
    p = base.state().pose
    return {"pose": [p.x, p.y, p.theta]}
