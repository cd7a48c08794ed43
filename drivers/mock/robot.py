"""In-memory capabilities with scriptable outcomes: the mock backend.

Everything here is driven by :meth:`MockRobot.spin`, which advances a
:class:`~mmexec.drivers.interfaces.ManualClock` by one control period and then lets each
capability integrate that period. Nothing happens between spins, so tests are exact and
fast: no threads, no sleeping, no wall clock.

Outcomes are scripted through attributes that tests may change at any time, or from the
``mock:`` section of a run config (see :mod:`mmexec.drivers.mock.backend`):

* ``robot.arm.fail_moves = {1, 2}``: the arm's 1st and 2nd moves (1-based count of
  :meth:`MockArm.follow` calls) abort part way with ``robot.arm.fail_reason``;
* ``robot.gripper.grasps = [False, True]``: the 1st close finds nothing, the 2nd closes on
  an object; later closes use ``robot.gripper.default_grasp``;
* ``robot.base.blocked = True``: the base refuses to move and reports a bumper fault;
* ``robot.camera.dropouts = {2}``: the 2nd call of :meth:`MockCamera.frame` returns None;
* ``robot.head.fail_moves = {1}``: the head's 1st :meth:`MockHead.point` fails part way
  (a robot built with ``"head"`` among its capabilities).

Units and frames are those of :mod:`mmexec.drivers.interfaces` (SI, REP-103).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from mmexec.drivers.descriptions import RobotDescription, locobot_wx250s
from mmexec.drivers.descriptions.head import HeadModel
from mmexec.drivers.geometry import wrap_angle
from mmexec.drivers.interfaces import (
    Arm,
    Base,
    BaseState,
    Camera,
    CameraFrame,
    CameraIntrinsics,
    Goal,
    GoalState,
    GraspState,
    Gripper,
    GripperState,
    Head,
    HeadState,
    JointLimit,
    JointState,
    JointTrajectory,
    LaserScan,
    Lidar,
    ManualClock,
    Pose2D,
    Robot,
)

__all__ = [
    "DEFAULT_ARM_LIMITS",
    "MockArm",
    "MockBase",
    "MockCamera",
    "MockGripper",
    "MockHead",
    "MockLidar",
    "MockRobot",
]

log = logging.getLogger(__name__)

#: A WidowX-250 6DOF-like arm: (name, lower, upper) [rad], velocity pi rad/s each.
DEFAULT_ARM_LIMITS: tuple[JointLimit, ...] = tuple(
    JointLimit(name, lo, hi, velocity=math.pi)
    for name, lo, hi in (
        ("waist", -math.pi, math.pi),
        ("shoulder", -1.88, 1.99),
        ("elbow", -2.15, 1.61),
        ("forearm_roll", -math.pi, math.pi),
        ("wrist_angle", -1.75, 2.15),
        ("wrist_rotate", -math.pi, math.pi),
    )
)


def _approach(value: float, target: float, max_step: float) -> float:
    if target > value:
        return min(target, value + max_step)
    return max(target, value - max_step)


# --------------------------------------------------------------------------- base

#: Default start pose of :class:`MockBase` (immutable, so one shared instance is fine).
_ORIGIN = Pose2D()


class MockBase(Base):
    """Differential base integrating the commanded (v, w) with acceleration limits.

    Commands are clamped to :attr:`max_linear` [m/s] / :attr:`max_angular` [rad/s] and
    dropped after :attr:`command_timeout` [s] of clock time without a new command.
    Poses are in ``map``; the mock's odometry is perfect.
    """

    def __init__(self, clock: ManualClock, *, start: Pose2D = _ORIGIN, blocked: bool = False) -> None:
        self._clock = clock
        self.pose = start
        self.v = 0.0
        self.w = 0.0
        self._cmd = (0.0, 0.0)
        self._cmd_t = -math.inf
        #: Scripted: while True the base does not move and reports ``bumper_centre``.
        self.blocked = blocked
        #: Number of :meth:`set_velocity` calls with a non-zero command (for tests).
        self.commands = 0
        #: Number of :meth:`stop` calls (for tests: a cancelled drive stops the base).
        self.stops = 0

    def state(self) -> BaseState:
        faults = frozenset({"bumper_centre"}) if self.blocked else frozenset()
        return BaseState(self.pose, self.v, self.w, self._clock.now(), faults)

    def set_velocity(self, v: float, w: float) -> None:
        v = max(-self.max_linear, min(self.max_linear, float(v)))
        w = max(-self.max_angular, min(self.max_angular, float(w)))
        if v != 0.0 or w != 0.0:
            self.commands += 1
        self._cmd = (v, w)
        self._cmd_t = self._clock.now()

    def stop(self) -> None:
        self.stops += 1
        self._cmd = (0.0, 0.0)
        self._cmd_t = self._clock.now()

    def step(self, dt: float) -> None:
        """Integrate ``dt`` seconds (called by :meth:`MockRobot.spin` after the clock moved)."""
        now = self._clock.now()
        target_v, target_w = self._cmd
        if now - self._cmd_t > self.command_timeout:
            target_v = target_w = 0.0
        if self.blocked:
            self.v = self.w = 0.0
            return
        self.v = _approach(self.v, target_v, self.max_linear_accel * dt)
        self.w = _approach(self.w, target_w, self.max_angular_accel * dt)
        th = self.pose.theta + 0.5 * self.w * dt  # midpoint heading
        self.pose = Pose2D(
            self.pose.x + self.v * dt * math.cos(th),
            self.pose.y + self.v * dt * math.sin(th),
            wrap_angle(self.pose.theta + self.w * dt),
        )


# --------------------------------------------------------------------------- arm


class _ArmMotion:
    def __init__(self, goal: Goal, traj: JointTrajectory, start_q: tuple[float, ...], t0: float,
                 fail_at: float | None, fail_reason: str) -> None:
        self.goal = goal
        self.traj = traj
        self.start_q = start_q
        self.t0 = t0
        self.fail_at = fail_at  # clock seconds after t0, or None
        self.fail_reason = fail_reason
        self.stop_deadline: float | None = None

    def position(self, t: float) -> tuple[float, ...]:
        first = self.traj.times[0]
        if t < first:
            a = max(0.0, t) / first
            return tuple(q0 + a * (q1 - q0) for q0, q1 in zip(self.start_q, self.traj.positions[0]))
        return self.traj.sample(t)


class MockArm(Arm):
    """A serial arm that follows joint trajectories in clock time.

    Trajectories that leave the joint range or exceed a velocity limit fail at once,
    naming the joint. A scripted failing move (see :attr:`fail_moves`) stops the arm at
    ``fail_at`` of the trajectory's duration and fails with :attr:`fail_reason`.
    Cancelling holds the arm where it is and reports CANCELLED after
    :attr:`stop_time` clock seconds (the deceleration of a real arm).
    """

    def __init__(
        self,
        clock: ManualClock,
        *,
        limits: Sequence[JointLimit] = DEFAULT_ARM_LIMITS,
        start: Sequence[float] | None = None,
        fail_moves: Iterable[int] = (),
        fail_reason: str = "trajectory aborted: joint following error",
        fail_at: float = 0.5,
        stop_time: float = 0.2,
    ) -> None:
        self._clock = clock
        self._limits = tuple(limits)
        self._names = tuple(lim.name for lim in self._limits)
        q = tuple(float(x) for x in (start if start is not None else [0.0] * len(self._limits)))
        if len(q) != len(self._limits):
            raise ValueError(f"MockArm: start has {len(q)} values for {len(self._limits)} joints")
        self._q = q
        self._qd = tuple(0.0 for _ in q)
        self._motion: _ArmMotion | None = None
        #: Scripted: 1-based indices of :meth:`follow` calls that fail part way.
        self.fail_moves: set[int] = set(fail_moves)
        self.fail_reason = fail_reason
        #: Fraction (0, 1] of a failing move's duration after which it fails.
        self.fail_at = fail_at
        #: Clock seconds a cancelled move takes to come to rest.
        self.stop_time = stop_time
        #: Number of :meth:`follow` calls so far (including rejected ones).
        self.moves = 0
        #: Number of goals cancelled (cancel requests that reached an active goal).
        self.cancels = 0

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._names

    @property
    def limits(self) -> tuple[JointLimit, ...]:
        return self._limits

    @property
    def busy(self) -> bool:
        """True while a goal is active or cancelling."""
        return self._motion is not None

    def state(self) -> JointState:
        n = len(self._q)
        return JointState(self._names, self._q, self._qd, (0.0,) * n, self._clock.now())

    def follow(self, trajectory: JointTrajectory) -> Goal:
        self.moves += 1
        index = self.moves
        name = f"arm move {index}"
        if tuple(trajectory.joint_names) != self._names:
            return Goal.failed(name, f"joint names {list(trajectory.joint_names)} != {list(self._names)}")
        problem = self._check(trajectory)
        if problem:
            return Goal.failed(name, problem)
        if self._motion is not None:
            # a new trajectory preempts the old one, as a real controller does
            self._motion.goal.mark_cancelled("preempted by a new trajectory")
            self._motion = None
        goal = Goal(name, on_cancel=self._on_cancel)
        fail_at = trajectory.duration * self.fail_at if index in self.fail_moves else None
        reason = f"{self.fail_reason} (scripted, move {index})"
        self._motion = _ArmMotion(goal, trajectory, self._q, self._clock.now(), fail_at, reason)
        return goal

    def stop(self) -> None:
        if self._motion is not None:
            self._motion.goal.mark_cancelled("arm stopped")
            self._motion = None
        self._qd = tuple(0.0 for _ in self._q)

    def _check(self, traj: JointTrajectory) -> str:
        prev_q, prev_t = self._q, 0.0
        for t, q in zip(traj.times, traj.positions):
            for lim, a, b in zip(self._limits, prev_q, q):
                if not lim.contains(b):
                    return f"joint {lim.name!r} target {b:.3f} rad outside [{lim.lower:.3f}, {lim.upper:.3f}]"
                speed = abs(b - a) / (t - prev_t)
                if speed > lim.velocity * (1.0 + 1e-6):
                    return f"joint {lim.name!r} needs {speed:.3f} rad/s, over its {lim.velocity:.3f} rad/s limit"
            prev_q, prev_t = q, t
        return ""

    def _on_cancel(self, goal: Goal) -> None:
        self.cancels += 1
        motion = self._motion
        if motion is None or motion.goal is not goal:
            goal.mark_cancelled("cancelled")
            return
        if self.stop_time <= 0.0:
            goal.mark_cancelled("cancelled")
            self._motion = None
            self._qd = tuple(0.0 for _ in self._q)
            return
        motion.stop_deadline = self._clock.now() + self.stop_time

    def step(self, dt: float) -> None:
        """Advance the active motion to the current clock time."""
        motion = self._motion
        if motion is None:
            return
        now = self._clock.now()
        if motion.stop_deadline is not None:
            self._qd = tuple(0.0 for _ in self._q)
            if now >= motion.stop_deadline - 1e-12:
                motion.goal.mark_cancelled("cancelled")
                self._motion = None
            return
        t = now - motion.t0
        if motion.fail_at is not None and t >= motion.fail_at:
            self._set_q(motion.position(motion.fail_at), dt)
            self._qd = tuple(0.0 for _ in self._q)
            motion.goal.fail(motion.fail_reason)
            self._motion = None
            return
        self._set_q(motion.position(t), dt)
        if t >= motion.traj.duration - 1e-12:
            self._qd = tuple(0.0 for _ in self._q)
            motion.goal.succeed(self.state())
            self._motion = None

    def _set_q(self, q: tuple[float, ...], dt: float) -> None:
        if dt > 0:
            self._qd = tuple((b - a) / dt for a, b in zip(self._q, q))
        self._q = tuple(float(x) for x in q)


# --------------------------------------------------------------------------- gripper


class _GripperMotion:
    def __init__(self, goal: Goal, target: float, speed: float, stop_at: float | None) -> None:
        self.goal = goal
        self.target = target
        self.speed = speed
        self.stop_at = stop_at  # width at which an object stops the fingers, or None


class MockGripper(Gripper):
    """A parallel gripper whose closes find an object or not, as scripted.

    A move towards a smaller width is a *close*; the n-th close (1-based) meets an object
    of :attr:`object_width` [m] when ``grasps[n-1]`` is True (``default_grasp`` beyond the
    list) and then stops there with ``CONTACT_CLOSING``; otherwise it reaches the width
    with ``AT_POSITION``. Moves listed in :attr:`fault_moves` (1-based over all moves)
    fail with a fault.
    """

    def __init__(
        self,
        clock: ManualClock,
        *,
        width: float = 0.085,
        grasps: Iterable[bool] = (),
        default_grasp: bool = True,
        object_width: float = 0.03,
        fault_moves: Iterable[int] = (),
    ) -> None:
        self._clock = clock
        self._width = float(width)
        self._grasp = GraspState.AT_POSITION
        self._motion: _GripperMotion | None = None
        self.grasps: list[bool] = list(grasps)
        self.default_grasp = default_grasp
        self.object_width = object_width
        self.fault_moves: set[int] = set(fault_moves)
        #: Number of :meth:`move` calls / of closes so far.
        self.moves = 0
        self.closes = 0

    def state(self) -> GripperState:
        return GripperState(self._width, self._grasp, self._clock.now())

    def move(self, width: float, *, speed: float = 0.1, force: float = 50.0) -> Goal:
        self.moves += 1
        name = f"gripper move {self.moves}"
        if not self.min_width - 1e-9 <= width <= self.max_width + 1e-9:
            return Goal.failed(name, f"width {width:.4f} m outside [{self.min_width}, {self.max_width}]")
        if speed <= 0.0:
            return Goal.failed(name, f"speed {speed} m/s must be > 0")
        if not 0.0 < force <= self.max_force:
            return Goal.failed(name, f"force {force} N outside (0, {self.max_force}]")
        if self.moves in self.fault_moves:
            return Goal.failed(name, f"gripper fault (scripted, move {self.moves})")
        if self._motion is not None:
            self._motion.goal.mark_cancelled("preempted by a new gripper move")
        stop_at = None
        if width < self._width:
            self.closes += 1
            i = self.closes - 1
            has_object = self.grasps[i] if i < len(self.grasps) else self.default_grasp
            if has_object and width < self.object_width < self._width + 1e-12:
                stop_at = self.object_width
        goal = Goal(name, on_cancel=self._on_cancel)
        self._motion = _GripperMotion(goal, float(width), float(speed), stop_at)
        self._grasp = GraspState.MOVING
        return goal

    def _on_cancel(self, goal: Goal) -> None:
        goal.mark_cancelled("cancelled")
        if self._motion is not None and self._motion.goal is goal:
            self._motion = None
            self._grasp = GraspState.AT_POSITION

    def step(self, dt: float) -> None:
        """Move the fingers for ``dt`` seconds."""
        m = self._motion
        if m is None:
            return
        end = m.target if m.stop_at is None else m.stop_at
        self._width = _approach(self._width, end, m.speed * dt)
        if abs(self._width - end) < 1e-12:
            self._grasp = GraspState.AT_POSITION if m.stop_at is None else GraspState.CONTACT_CLOSING
            self._motion = None
            m.goal.succeed(self.state())


# --------------------------------------------------------------------------- head


class MockHead(Head):
    """A pan/tilt head moving both joints straight to the target at their velocity limit
    in clock time. ``kinematics`` (a :class:`HeadModel`, e.g. the LoCoBot's) gives the
    limits and the camera pose; targets outside the limits fail at once. A scripted
    failing move (:attr:`fail_moves`, 1-based over :meth:`point` calls) stops half way and
    fails. Cancel holds at once."""

    def __init__(self, clock: ManualClock, kinematics: HeadModel, *, home: tuple[float, float] = (0.0, 0.0),
                 fail_moves: Iterable[int] = ()) -> None:
        self._clock = clock
        self._model = kinematics
        self._home = (float(home[0]), float(home[1]))
        self._q = self._home
        self._goal: Goal | None = None
        self._target = self._q
        self._fail_at: tuple[float, float] | None = None
        #: Scripted: 1-based indices of :meth:`point` calls that fail half way.
        self.fail_moves: set[int] = set(fail_moves)
        #: Number of :meth:`point` calls so far (including refused ones), and the targets asked for.
        self.moves = 0
        self.targets: list[tuple[float, float]] = []

    @property
    def joint_names(self) -> tuple[str, str]:
        return self._model.joint_names

    @property
    def limits(self) -> tuple[JointLimit, JointLimit]:
        return self._model.limits

    @property
    def home(self) -> tuple[float, float]:
        return self._home

    @property
    def kinematics(self) -> HeadModel:
        return self._model

    @property
    def busy(self) -> bool:
        """True while a goal is active."""
        return self._goal is not None and not self._goal.done()

    def state(self) -> HeadState:
        return HeadState(self._q[0], self._q[1], self._clock.now())

    def point(self, pan: float, tilt: float) -> Goal:
        self.moves += 1
        self.targets.append((float(pan), float(tilt)))
        name = f"head move {self.moves}"
        problem = self.limit_problem(pan, tilt)
        if problem:
            return Goal.failed(name, problem)
        if self._goal is not None and not self._goal.done():
            self._goal.mark_cancelled("preempted by a new head goal")
        self._goal = Goal(name, on_cancel=self._on_cancel)
        self._target = (float(pan), float(tilt))
        self._fail_at = None
        if self.moves in self.fail_moves:
            self._fail_at = tuple((a + b) / 2.0 for a, b in zip(self._q, self._target))  # type: ignore[assignment]
        return self._goal

    def _on_cancel(self, goal: Goal) -> None:
        self._target = self._q
        goal.mark_cancelled("cancelled: head holding")

    def stop(self) -> None:
        if self._goal is not None and not self._goal.done():
            self._goal.cancel()

    def step(self, dt: float) -> None:
        """Move for ``dt`` seconds."""
        goal = self._goal
        if goal is None or goal.done():
            return
        end = self._fail_at if self._fail_at is not None else self._target
        self._q = tuple(_approach(q, t, lim.velocity * dt) for q, t, lim in zip(self._q, end, self.limits))  # type: ignore[assignment]
        if self._q == end:
            if self._fail_at is not None:
                goal.fail(f"head move failed (scripted, move {self.moves})")
            else:
                goal.succeed(self.state())


# --------------------------------------------------------------------------- sensors


class MockCamera(Camera):
    """An RGB-D camera returning synthetic frames: a deterministic gradient image and a
    flat depth of :attr:`depth` [m]. Calls listed in :attr:`dropouts` (1-based) return
    None, as does every call while :attr:`enabled` is False. Mounted 0.5 m above
    ``base_link`` looking along +x (optical z forward); on a :class:`MockHead` (``head``),
    at the head's optical frame for its current pan and tilt instead."""

    def __init__(
        self,
        clock: ManualClock,
        base: MockBase | None,
        *,
        width: int = 64,
        height: int = 48,
        hfov: float = 1.2,
        depth: float = 1.0,
        dropouts: Iterable[int] = (),
        head: MockHead | None = None,
    ) -> None:
        self._clock = clock
        self._base = base
        self.head = head
        self._intr = CameraIntrinsics.from_fov(width, height, hfov)
        self.depth = depth
        self.dropouts: set[int] = set(dropouts)
        self.enabled = True
        self.calls = 0
        T = np.eye(4)
        T[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        T[2, 3] = 0.5
        self._T = T

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._intr

    def pose_in_base(self) -> np.ndarray:
        if self.head is not None:
            st = self.head.state()
            return self.head.kinematics.T_root_optical(st.pan, st.tilt)
        return self._T.copy()

    def frame(self) -> CameraFrame | None:
        self.calls += 1
        if not self.enabled or self.calls in self.dropouts:
            return None
        w, h = self._intr.width, self._intr.height
        xs = np.linspace(0, 255, w, dtype=np.float32)
        ys = np.linspace(0, 255, h, dtype=np.float32)
        rgb = np.empty((h, w, 3), dtype=np.uint8)
        rgb[..., 0] = xs[None, :].astype(np.uint8)
        rgb[..., 1] = ys[:, None].astype(np.uint8)
        rgb[..., 2] = 128
        depth = np.full((h, w), self.depth, dtype=np.float32)
        T_map_base = self._base.pose.matrix() if self._base is not None else np.eye(4)
        return CameraFrame(rgb, depth, self._intr, self._clock.now(), self.pose_in_base(), T_map_base)


class MockLidar(Lidar):
    """A 360 degree scanner seeing a circular wall at :attr:`range` [m] (inf: nothing)."""

    def __init__(self, clock: ManualClock, *, rays: int = 360, range: float = 3.0, range_max: float = 8.0) -> None:
        self._clock = clock
        self.rays = rays
        self.range = range
        self.range_max = range_max
        self.enabled = True

    def scan(self) -> LaserScan | None:
        if not self.enabled:
            return None
        r = self.range if self.range <= self.range_max else math.inf
        ranges = np.full(self.rays, r, dtype=np.float32)
        return LaserScan(-math.pi, 2.0 * math.pi / self.rays, ranges, 0.05, self.range_max, self._clock.now())


# --------------------------------------------------------------------------- robot


class MockRobot(Robot):
    """The mock backend: a :class:`ManualClock` and in-memory capabilities.

    Pass ``capabilities`` to leave some out (``{"arm", "gripper"}`` is a fixed arm).
    ``description`` is the robot model skills plan for (default: the LoCoBot WX250s,
    whose arm joints the mock arm has; None: a robot without a description).
    :meth:`spin` advances the clock by ``period`` [s] and integrates every capability.
    Build one from a config section with :func:`mmexec.drivers.mock.backend.build`, or
    directly in tests::

        robot = MockRobot(profile={"named_poses": {"home": [0, 0, 0, 0, 0, 0]}})
        robot.arm.fail_moves = {1, 2}
    """

    ALL_CAPABILITIES = frozenset({"base", "arm", "gripper", "camera", "lidar"})
    #: capabilities a mock has only when asked for: ``head``, a :class:`MockHead` with the
    #: description's head chain (the camera then rides on it)
    OPTIONAL_CAPABILITIES = frozenset({"head"})

    def __init__(
        self,
        *,
        profile: Mapping[str, Any] | None = None,
        capabilities: Iterable[str] = ALL_CAPABILITIES,
        clock: ManualClock | None = None,
        name: str = "mock",
        description: RobotDescription | None = locobot_wx250s.DESCRIPTION,
    ) -> None:
        caps = set(capabilities)
        unknown = caps - self.ALL_CAPABILITIES - self.OPTIONAL_CAPABILITIES
        if unknown:
            raise ValueError(f"MockRobot: unknown capabilities {sorted(unknown)}")
        self.name = name
        self.description = description
        self.clock: ManualClock = clock if clock is not None else ManualClock()
        self.profile = dict(profile or {})
        self.base: MockBase | None = MockBase(self.clock) if "base" in caps else None  # type: ignore[assignment]
        self.arm: MockArm | None = MockArm(self.clock) if "arm" in caps else None  # type: ignore[assignment]
        self.gripper: MockGripper | None = MockGripper(self.clock) if "gripper" in caps else None  # type: ignore[assignment]
        model = HeadModel.of(description) if "head" in caps and description is not None else None
        if "head" in caps and model is None:
            raise ValueError(f"MockRobot: a head needs a description with pan/tilt joints, got {description}")
        self.head: MockHead | None = MockHead(self.clock, model) if model is not None else None  # type: ignore[assignment]
        self.camera: MockCamera | None = (  # type: ignore[assignment]
            MockCamera(self.clock, self.base, head=self.head) if "camera" in caps else None)
        self.lidar: MockLidar | None = MockLidar(self.clock) if "lidar" in caps else None  # type: ignore[assignment]
        self.closed = False
        self.safe_stops = 0
        self.spins = 0

    def spin(self, period: float) -> None:
        """Advance the clock by ``period`` seconds (> 0) and integrate every capability."""
        if not period > 0.0:
            raise ValueError(f"spin period must be > 0 s, got {period}")
        self.clock.advance(period)
        self.spins += 1
        for cap in (self.base, self.arm, self.gripper, self.head):
            if cap is not None:
                cap.step(period)

    def safe_stop(self) -> None:
        self.safe_stops += 1
        super().safe_stop()

    def close(self) -> None:
        super().close()
        self.closed = True

    def active_goals(self) -> list[Goal]:
        """Goals still running or stopping (empty when every motion has ended)."""
        out: list[Goal] = []
        for cap in (self.arm, self.gripper):
            motion = getattr(cap, "_motion", None) if cap is not None else None
            if motion is not None and motion.goal.state in (GoalState.ACTIVE, GoalState.CANCELLING):
                out.append(motion.goal)
        if self.head is not None and self.head.busy:
            out.append(self.head._goal)  # type: ignore[arg-type]
        return out
