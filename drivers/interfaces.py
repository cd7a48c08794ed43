"""Capability interfaces shared by the real drivers, the pybullet backend and the mocks.

Skills talk only to these. Every long action is a :class:`Goal`: started by a call that
returns at once, polled each tick, cancelled on demand. Nothing here blocks.

Units are SI (m, rad, s, N) and frames follow REP-103 (x forward, y left, z up):

* ``map``: the fixed world frame the mission's poses are given in.
* ``base_link``: the mobile base, on the floor plane (``base_footprint`` in ROS terms).
* ``arm_base``: the arm's mounting frame (``arm_base_link`` on the LoCoBot, ``base_link``
  of the UR); its pose in ``base_link`` is :attr:`Arm.mount`.
* camera optical frame: z forward, x right, y down; its pose in ``base_link`` is
  :meth:`Camera.pose_in_base` (on a pan/tilt :class:`Head`, at the head's measured joints).

Transforms are 4x4 homogeneous ``numpy`` arrays named ``T_<to>_<from>``: a point in
``from`` coordinates, multiplied on the left by ``T_to_from``, lands in ``to``.
"""

from __future__ import annotations

import abc
import enum
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Self

import numpy as np

from mmexec.drivers.geometry import planar_transform

if TYPE_CHECKING:  # the descriptions use JointLimit from here: no import at run time
    from mmexec.drivers.descriptions import RobotDescription

__all__ = [
    "BLIND_FAULTS",
    "Arm",
    "Base",
    "BaseState",
    "Camera",
    "CameraFrame",
    "CameraIntrinsics",
    "CapabilityError",
    "Clock",
    "Goal",
    "GoalState",
    "GraspState",
    "Gripper",
    "GripperState",
    "Head",
    "HeadState",
    "JointLimit",
    "JointState",
    "JointTrajectory",
    "LaserScan",
    "Lidar",
    "ManualClock",
    "MonotonicClock",
    "OccupancyGrid",
    "Pose2D",
    "ReflectorPost",
    "Robot",
    "SceneBox",
]


class CapabilityError(RuntimeError):
    """A capability cannot do what was asked (absent, not ready, bad argument).

    Raised synchronously by the call that asked, with a message that says what to do.
    Failures that happen *during* a goal are reported through :class:`Goal` instead.
    """


# --------------------------------------------------------------------------- clock


class Clock(abc.ABC):
    """Time source for everything time-dependent: stepped in sim, monotonic on the robot.

    ``stepped``: True when time moves only when the backend advances it (the simulator,
    mocks), never while code runs. A skill waiting for off-thread work (planning) may then
    wait for it in wall time within one tick without the clock moving, which keeps a
    seeded run exactly reproducible; on a wall clock it must not."""

    stepped: bool = False

    @abc.abstractmethod
    def now(self) -> float:
        """Seconds since an arbitrary epoch fixed for the run (monotonic, never jumps back)."""


class MonotonicClock(Clock):
    """The real robot's clock: ``time.monotonic()`` seconds (never jumps with NTP)."""

    def now(self) -> float:
        return time.monotonic()


class ManualClock(Clock):
    """A clock that only moves when told to: for mocks, fakes and tests."""

    stepped = True

    def __init__(self, start: float = 0.0) -> None:
        self._t = float(start)
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            return self._t

    def advance(self, dt: float) -> float:
        """Move time forward by ``dt`` seconds (>= 0) and return the new time."""
        if dt < 0:
            raise ValueError(f"clock cannot go backwards (dt={dt})")
        with self._lock:
            self._t += dt
            return self._t


# --------------------------------------------------------------------------- goals


class GoalState(enum.Enum):
    """Lifecycle of a long action. ``CANCELLING`` lasts while the device stops safely."""

    ACTIVE = "active"
    CANCELLING = "cancelling"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"

    @property
    def done(self) -> bool:
        return self in (GoalState.SUCCEEDED, GoalState.FAILED, GoalState.CANCELLED)


class Goal:
    """Handle on a long action running in a backend (a trajectory, a gripper move, ...).

    The caller polls :attr:`state` (or :meth:`done`) every tick and may :meth:`cancel`.
    The backend drives the handle with :meth:`succeed`, :meth:`fail` and
    :meth:`mark_cancelled`. Cancellation is two-phase: :meth:`cancel` moves an active goal
    to ``CANCELLING`` and calls the backend's ``on_cancel`` once; the backend calls
    :meth:`mark_cancelled` when the device has actually stopped (possibly several ticks
    later). Backends that compute progress lazily pass ``on_poll``, called on every
    state read. Thread-safe: drivers finish goals from their I/O threads.
    """

    def __init__(
        self,
        name: str,
        *,
        on_cancel: Callable[[Goal], None] | None = None,
        on_poll: Callable[[Goal], None] | None = None,
    ) -> None:
        self.name = name
        self._state = GoalState.ACTIVE
        self._reason = ""
        self._result: Any = None
        self._on_cancel = on_cancel
        self._on_poll = on_poll
        self._lock = threading.RLock()

    def __repr__(self) -> str:
        return f"Goal({self.name!r}, {self._state.value}{', ' + self._reason if self._reason else ''})"

    # -- caller side
    @property
    def state(self) -> GoalState:
        poll = self._on_poll
        if poll is not None and not self._state.done:
            poll(self)
        with self._lock:
            return self._state

    def done(self) -> bool:
        """True once the goal succeeded, failed or finished cancelling."""
        return self.state.done

    @property
    def reason(self) -> str:
        """Human-readable failure reason ("" unless FAILED or CANCELLED)."""
        with self._lock:
            return self._reason

    @property
    def result(self) -> Any:
        """Backend-specific result once SUCCEEDED (e.g. a :class:`GripperState`)."""
        with self._lock:
            return self._result

    def cancel(self) -> None:
        """Ask the backend to stop. Idempotent; a finished goal ignores it."""
        with self._lock:
            if self._state is not GoalState.ACTIVE:
                return
            self._state = GoalState.CANCELLING
            cb = self._on_cancel
        if cb is not None:
            cb(self)
        else:
            self.mark_cancelled("cancelled")

    # -- backend side
    def succeed(self, result: Any = None) -> None:
        with self._lock:
            if self._state.done:
                return
            if self._state is GoalState.CANCELLING:
                # the device finished the motion while stopping: it has stopped either way
                self._state, self._reason = GoalState.CANCELLED, "cancelled"
                return
            self._state, self._result = GoalState.SUCCEEDED, result

    def fail(self, reason: str) -> None:
        with self._lock:
            if self._state.done:
                return
            self._state, self._reason = GoalState.FAILED, reason

    def mark_cancelled(self, reason: str = "cancelled") -> None:
        with self._lock:
            if self._state.done:
                return
            self._state, self._reason = GoalState.CANCELLED, reason

    @classmethod
    def finished(cls, name: str, result: Any = None) -> Goal:
        """A goal that already succeeded (for actions that complete instantly)."""
        g = cls(name)
        g.succeed(result)
        return g

    @classmethod
    def failed(cls, name: str, reason: str) -> Goal:
        """A goal that already failed (e.g. a precondition checked at start)."""
        g = cls(name)
        g.fail(reason)
        return g


# --------------------------------------------------------------------------- messages


@dataclass(frozen=True)
class Pose2D:
    """Planar pose: x, y [m] and heading theta [rad] (CCW from +x)."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0

    def matrix(self) -> np.ndarray:
        """4x4 transform of this pose (``T_parent_self``), z = 0."""
        return planar_transform(self.x, self.y, self.theta)

    def distance_to(self, other: Pose2D) -> float:
        return math.hypot(other.x - self.x, other.y - self.y)


#: Base faults after which the reported velocity is no measurement (the link to the base is
#: gone or its driver failed): a skill braking the base commands zero and does not wait to
#: see it at rest, since it cannot see it (the driver keeps sending stops on its own).
BLIND_FAULTS: frozenset[str] = frozenset({"link_lost", "driver_error"})


@dataclass(frozen=True)
class BaseState:
    """Mobile base state at ``stamp`` [s, clock time].

    ``pose`` is the base's best pose estimate in ``map`` (odometry plus whatever
    localisation the backend has); ``v`` [m/s], ``w`` [rad/s] measured velocity.
    ``faults`` names active safety conditions, e.g. ``{"bumper_left", "cliff_centre",
    "wheel_drop_right", "overcurrent_left", "link_lost"}``; any fault stops the base.

    With a localiser (the run config's ``localization:``, docs/localization.md), ``pose``
    is the odometry pose corrected by the localiser's ``map -> odom`` transform,
    ``covariance`` its 3x3 covariance over ``(x [m], y [m], theta [rad])`` as row tuples,
    and ``localised`` False while the filter has not converged (the pose must not be
    trusted to drive on the map). Without one, ``covariance`` is None (no estimate of the
    odometry's drift) and ``localised`` True: the odometry is the map pose.
    """

    pose: Pose2D
    v: float
    w: float
    stamp: float
    faults: frozenset[str] = frozenset()
    covariance: tuple[tuple[float, float, float], ...] | None = None
    localised: bool = True


@dataclass(frozen=True)
class JointLimit:
    """Position [rad or m], velocity [rad/s or m/s], acceleration [rad/s^2] limits of a joint."""

    name: str
    lower: float
    upper: float
    velocity: float
    acceleration: float = math.inf
    effort: float = math.inf

    def contains(self, q: float, tol: float = 1e-9) -> bool:
        return self.lower - tol <= q <= self.upper + tol


@dataclass(frozen=True)
class JointState:
    """Arm joint state at ``stamp``: positions [rad], velocities [rad/s], efforts [N m or A]."""

    names: tuple[str, ...]
    positions: tuple[float, ...]
    velocities: tuple[float, ...]
    efforts: tuple[float, ...]
    stamp: float

    def as_dict(self) -> dict[str, float]:
        return dict(zip(self.names, self.positions))


@dataclass(frozen=True)
class JointTrajectory:
    """Timed joint-space waypoints.

    ``times`` [s] are relative to the start of execution, strictly increasing, the first
    one > 0 (the arm starts from where it is). ``positions[i]`` is the full joint vector
    (in :attr:`Arm.joint_names` order) to reach at ``times[i]``.
    """

    joint_names: tuple[str, ...]
    times: tuple[float, ...]
    positions: tuple[tuple[float, ...], ...]

    def __post_init__(self) -> None:
        if len(self.times) != len(self.positions):
            raise ValueError("JointTrajectory: times and positions differ in length")
        if not self.times:
            raise ValueError("JointTrajectory: no waypoints")
        if any(len(p) != len(self.joint_names) for p in self.positions):
            raise ValueError("JointTrajectory: a waypoint has the wrong number of joints")
        prev = 0.0
        for t in self.times:
            if not t > prev:
                raise ValueError("JointTrajectory: times must be > 0 and strictly increasing")
            prev = t

    @property
    def duration(self) -> float:
        return self.times[-1]

    def sample(self, t: float) -> tuple[float, ...]:
        """Linear interpolation at ``t`` seconds after start (clamped to the ends).

        Before the first waypoint the trajectory holds the first waypoint; callers that
        need the segment from the current position interpolate it themselves.
        """
        if t <= self.times[0]:
            return self.positions[0]
        if t >= self.times[-1]:
            return self.positions[-1]
        i = int(np.searchsorted(self.times, t))
        t0, t1 = self.times[i - 1], self.times[i]
        a = (t - t0) / (t1 - t0)
        p0, p1 = self.positions[i - 1], self.positions[i]
        return tuple(x0 + a * (x1 - x0) for x0, x1 in zip(p0, p1))


class GraspState(enum.Enum):
    """What the gripper's fingers found (Robotiq gOBJ semantics, generalised)."""

    MOVING = "moving"
    CONTACT_OPENING = "contact_opening"   # stopped by an object while opening (outer grip)
    CONTACT_CLOSING = "contact_closing"   # stopped by an object while closing (inner grip)
    AT_POSITION = "at_position"           # reached the requested width: no object, or lost
    DROPPED = "dropped"                   # had an object, lost it since


@dataclass(frozen=True)
class GripperState:
    """Finger opening ``width`` [m, gap between pads], grasp state, ``stamp`` [s]."""

    width: float
    grasp: GraspState
    stamp: float
    fault: str = ""

    @property
    def holding(self) -> bool:
        return self.grasp in (GraspState.CONTACT_CLOSING, GraspState.CONTACT_OPENING)


@dataclass(frozen=True)
class HeadState:
    """Pan/tilt head state at ``stamp`` [s, clock time], measured: ``pan`` [rad] about the
    head's vertical axis (positive turns the camera left, CCW seen from above), ``tilt``
    [rad] about its horizontal axis (positive looks down), their velocities [rad/s], and
    ``fault`` ("" when none: e.g. a servo's hardware error, the link lost)."""

    pan: float
    tilt: float
    stamp: float
    pan_velocity: float = 0.0
    tilt_velocity: float = 0.0
    fault: str = ""


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics in pixels; ``dist`` are OpenCV distortion coefficients."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @classmethod
    def from_fov(cls, width: int, height: int, hfov: float) -> CameraIntrinsics:
        """Square-pixel intrinsics from a horizontal field of view [rad]."""
        f = (width / 2.0) / math.tan(hfov / 2.0)
        return cls(width, height, f, f, (width - 1) / 2.0, (height - 1) / 2.0)


@dataclass(frozen=True)
class CameraFrame:
    """One camera frame.

    ``rgb``: HxWx3 uint8 (RGB order). ``depth``: HxW float32 metres along the optical z
    axis, registered to ``rgb``, ``nan`` where unknown; None for an RGB-only camera.
    ``T_base_camera``: optical frame pose in ``base_link`` at ``stamp``;
    ``T_map_base``: base pose in ``map`` at ``stamp`` (from :class:`BaseState`).
    """

    rgb: np.ndarray
    depth: np.ndarray | None
    intrinsics: CameraIntrinsics
    stamp: float
    T_base_camera: np.ndarray
    T_map_base: np.ndarray = field(default_factory=lambda: np.eye(4))


@dataclass(frozen=True)
class LaserScan:
    """Planar scan in the lidar frame, CCW angles [rad], ranges [m] (inf = no return)."""

    angle_min: float
    angle_increment: float
    ranges: np.ndarray
    range_min: float
    range_max: float
    stamp: float
    T_base_lidar: np.ndarray = field(default_factory=lambda: np.eye(4))
    #: per-beam return intensity in [0, 1] (same length as ``ranges``; 0 = no return,
    #: 1 = retro-reflector), or None when the sensor gives none
    intensities: np.ndarray | None = None

    @property
    def angles(self) -> np.ndarray:
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges))


@dataclass(frozen=True)
class ReflectorPost:
    """A laser-reflector post (a cylinder under retro-reflective tape) at a known place:
    ``name``, centre ``position`` ``(x, y)`` in ``map`` [m], ``radius`` [m]."""

    name: str
    position: tuple[float, float]
    radius: float


@dataclass(frozen=True)
class OccupancyGrid:
    """A 2D map in ``map`` (map_server convention): ``data[row, col]`` with row 0 at
    ``origin`` y (rows grow along +y), values 0 free, 100 occupied, -1 unknown;
    ``resolution`` [m/cell]; ``origin`` is the pose of cell (0, 0)'s corner.
    ``reflectors``: the laser-reflector posts of the map (landmarks for the localiser;
    a map file's ``reflectors:`` key, a sim world's posts), empty when it has none."""

    data: np.ndarray
    resolution: float
    origin: Pose2D = Pose2D()
    reflectors: tuple[ReflectorPost, ...] = ()

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        return int(self.data.shape[0])


@dataclass(frozen=True)
class SceneBox:
    """A static box obstacle known in advance (shelf board, table, wall), for planning.

    ``pose`` is the box centre as a 4x4 ``T_map_box``; ``size`` full extents [m].
    """

    name: str
    pose: np.ndarray
    size: tuple[float, float, float]


# --------------------------------------------------------------------------- capabilities


class Base(abc.ABC):
    """Differential-drive mobile base.

    Velocity commands are held only for :attr:`command_timeout` seconds: a skill that
    keeps driving repeats its command every tick. The backend clamps to its limits.
    """

    max_linear: float = 0.7       # m/s
    max_angular: float = math.pi  # rad/s
    max_linear_accel: float = 1.0     # m/s^2
    max_angular_accel: float = 3.5    # rad/s^2
    radius: float = 0.178         # m, circumscribed footprint radius
    command_timeout: float = 0.6  # s

    @abc.abstractmethod
    def state(self) -> BaseState:
        """Latest pose / velocity / faults. Never blocks."""

    @abc.abstractmethod
    def set_velocity(self, v: float, w: float) -> None:
        """Command forward speed ``v`` [m/s] and yaw rate ``w`` [rad/s] (clamped)."""

    def stop(self) -> None:
        """Command zero velocity at once."""
        self.set_velocity(0.0, 0.0)


class Arm(abc.ABC):
    """A serial arm executing timed joint trajectories.

    The backend enforces joint-range, velocity and acceleration limits itself: a
    trajectory that leaves the range or exceeds velocity limits fails at once (its goal is
    FAILED with the offending joint named) and nothing moves. Cancelling a goal
    decelerates the arm and holds position; the goal reaches CANCELLED once stopped.
    """

    @property
    @abc.abstractmethod
    def joint_names(self) -> tuple[str, ...]:
        """Controlled joints, in command order (no gripper, no shadow servos)."""

    @property
    @abc.abstractmethod
    def limits(self) -> tuple[JointLimit, ...]:
        """Limits per joint, in :attr:`joint_names` order."""

    @property
    def mount(self) -> np.ndarray:
        """``T_base_armbase``: the arm mount frame in ``base_link`` (4x4)."""
        return np.eye(4)

    @abc.abstractmethod
    def state(self) -> JointState:
        """Latest joint state. Never blocks."""

    @abc.abstractmethod
    def follow(self, trajectory: JointTrajectory) -> Goal:
        """Start executing ``trajectory``; the goal succeeds when the last waypoint is reached."""

    def move_to(self, q: Sequence[float], *, speed_scale: float = 0.5) -> Goal:
        """Move in joint space to ``q`` along a straight line, at ``speed_scale`` of the
        slowest joint's velocity limit (0 < speed_scale <= 1)."""
        if not 0.0 < speed_scale <= 1.0:
            return Goal.failed("move_to", f"speed_scale {speed_scale} outside (0, 1]")
        current = self.state().positions
        if len(q) != len(current):
            return Goal.failed("move_to", f"expected {len(current)} joint values, got {len(q)}")
        dur = 0.0
        for lim, a, b in zip(self.limits, current, q):
            dur = max(dur, abs(b - a) / (lim.velocity * speed_scale))
        dur = max(dur, 0.05)
        traj = JointTrajectory(self.joint_names, (dur,), (tuple(float(x) for x in q),))
        return self.follow(traj)

    def stop(self) -> None:
        """Stop any motion and hold position (used on errors and shutdown)."""


class Gripper(abc.ABC):
    """Parallel gripper. ``width`` is the gap between the finger pads [m]."""

    min_width: float = 0.0
    max_width: float = 0.085
    max_force: float = 235.0   # N

    @abc.abstractmethod
    def state(self) -> GripperState:
        """Latest state. Never blocks."""

    @abc.abstractmethod
    def move(self, width: float, *, speed: float = 0.1, force: float = 50.0) -> Goal:
        """Go to ``width`` [m] at ``speed`` [m/s], stopping on contact at ``force`` [N].

        The goal succeeds when the fingers stop (at the width or on an object); its result
        is the :class:`GripperState` then (``grasp`` tells which). It fails on a fault.
        """

    def open(self, *, speed: float = 0.1, force: float = 50.0) -> Goal:
        return self.move(self.max_width, speed=speed, force=force)

    def close(self, *, speed: float = 0.1, force: float = 50.0) -> Goal:
        return self.move(self.min_width, speed=speed, force=force)


class Camera(abc.ABC):
    """An RGB or RGB-D camera fixed (or pan/tilt-mounted) on the robot."""

    @property
    @abc.abstractmethod
    def intrinsics(self) -> CameraIntrinsics: ...

    @abc.abstractmethod
    def pose_in_base(self) -> np.ndarray:
        """``T_base_camera`` (optical frame) now, 4x4."""

    @abc.abstractmethod
    def frame(self) -> CameraFrame | None:
        """The latest frame, or None when none is available (dropout, not started).

        The sim renders on demand here, so call it only when a frame is needed.
        """


class Head(abc.ABC):
    """A pan/tilt head carrying the camera (the LoCoBot's; None on a robot without one).

    :meth:`point` starts a move of both joints as a :class:`Goal` (polled each tick,
    cancelled on demand, never waited on); the backend enforces the joint limits itself: a
    target outside them gives a FAILED goal naming the joint, and nothing moves. The goal
    succeeds when both measured joints are within :attr:`tolerance` of the target; cancel
    holds the head where it is. :attr:`home` is the robot's default head pose (from its
    config or description), which skills that move the head return to. The camera's
    :meth:`Camera.pose_in_base` follows the head's measured joints, and every frame carries
    the pose at its capture. :attr:`kinematics` (the description's head chain, None when
    unknown) turns a point into the pan and tilt that look at it (:meth:`look_at`).
    """

    tolerance: float = 0.02  # rad

    @property
    @abc.abstractmethod
    def joint_names(self) -> tuple[str, str]:
        """The (pan, tilt) joint names of the robot description."""

    @property
    @abc.abstractmethod
    def limits(self) -> tuple[JointLimit, JointLimit]:
        """Pan and tilt limits (position [rad], velocity [rad/s]) from the description."""

    @property
    def home(self) -> tuple[float, float]:
        """The default head pose (pan, tilt) [rad]."""
        return (0.0, 0.0)

    @property
    def kinematics(self) -> Any:
        """The head's chain (:class:`mmexec.drivers.descriptions.head.HeadModel`), or None."""
        return None

    @abc.abstractmethod
    def state(self) -> HeadState:
        """Latest measured pan/tilt. Never blocks."""

    @abc.abstractmethod
    def point(self, pan: float, tilt: float) -> Goal:
        """Start moving to ``pan``, ``tilt`` [rad] at the joints' velocity limit."""

    def look_at(self, point_in_base: Sequence[float]) -> Goal:
        """Start pointing the camera's optical axis at ``point_in_base`` (x, y, z [m] in
        ``base_link``); a FAILED goal when the head cannot (no kinematics, out of reach)."""
        model = self.kinematics
        if model is None:
            return Goal.failed("head.look_at", "this head has no kinematic model to aim with")
        pan, tilt = model.aim(point_in_base)
        return self.point(pan, tilt)

    def limit_problem(self, pan: float, tilt: float) -> str:
        """Empty when ``pan``, ``tilt`` [rad] are within :attr:`limits`, else one line naming
        the joint (for the backends' checks)."""
        for lim, q in zip(self.limits, (pan, tilt)):
            if not math.isfinite(q) or not lim.contains(q):
                return (f"{lim.name} = {q:.4f} rad outside its limits [{lim.lower:.4f}, {lim.upper:.4f}] rad; "
                        "nothing was sent")
        return ""

    def stop(self) -> None:
        """Cancel any move and hold where the head is."""


class Lidar(abc.ABC):
    """A planar 360 degree scanner."""

    @abc.abstractmethod
    def scan(self) -> LaserScan | None:
        """The latest scan, or None when none is available."""


class Robot(abc.ABC):
    """A backend: the capabilities of one robot plus the loop hooks the runner needs.

    Absent capabilities are None (a fixed arm has no ``base``).
    ``profile`` is the robot profile from the config (named poses, mounts, skill
    defaults); its content is read by skills, not by the executive.
    ``description`` is the robot model's description (:mod:`mmexec.drivers.descriptions`:
    kinematics, limits, tool and grasp links, collision model), set by the backend from
    its config; None when the config names none. Skills take model facts from it and
    never decide by a model's name.
    """

    name: str = "robot"
    description: RobotDescription | None = None
    clock: Clock
    base: Base | None = None
    arm: Arm | None = None
    gripper: Gripper | None = None
    camera: Camera | None = None
    lidar: Lidar | None = None
    #: the camera's pan/tilt head (the LoCoBot's); None on a robot without one
    head: Head | None = None
    profile: dict[str, Any]
    #: prior knowledge of the environment, in ``map``: a navigation map (from the world in
    #: sim, from a map_server PGM + YAML on the robot) and static boxes for arm planning.
    occupancy: OccupancyGrid | None = None
    scene: tuple[SceneBox, ...] = ()

    @abc.abstractmethod
    def spin(self, period: float) -> None:
        """Advance one control period [s]: the sim steps physics by exactly ``period``
        of sim time; the real robot sleeps until the next period boundary; the mock
        advances its manual clock. Called by the runner between ticks, never by skills."""

    def safe_stop(self) -> None:
        """Stop every motion now and leave the robot safe (base stopped, arm and head
        holding, gripper unchanged). Must not raise."""
        for cap in (self.base, self.arm, self.head):
            if cap is None:
                continue
            try:
                cap.stop()
            except Exception:
                import logging

                logging.getLogger(__name__).exception("safe_stop: %s.stop() failed", cap)

    def close(self) -> None:
        """Stop motion and release every resource (ports, sockets, physics client)."""
        self.safe_stop()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
