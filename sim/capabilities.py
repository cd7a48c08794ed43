"""Capability implementations on pybullet: Base, Arm, Gripper, Head, Camera, Lidar, Clock.

All of them share one :class:`SimCore` (client id, robot body, link/joint indices, the
sim clock, the seeded generator, the fault injector). Nothing here steps physics by
itself: :meth:`mmexec.sim.backend.SimRobot.spin` calls each capability's ``update(dt)``
once per physics substep and then ``p.stepSimulation()``. Calls from skills only set
targets or read state, so they never block.

Frames: ``base_link`` in the interfaces is the model's root link (``base_footprint``,
on the floor). The robot is a fixed-base multibody moved kinematically: each substep
the base pose is integrated from the commanded velocity (within velocity and
acceleration limits) and the robot is placed there unless its body would intersect
static geometry (unmapped obstacles included) or a person (:mod:`mmexec.sim.people`), in
which case it stays and reports a bumper fault on the side of the contact. Every such
contact is also recorded on :attr:`SimCore.contacts` (ground truth, sim-only).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field, fields

import cv2
import numpy as np
import pybullet as p

from mmexec.drivers.geometry import position_quat, wrap_angle
from mmexec.drivers.interfaces import (
    Arm,
    Base,
    BaseState,
    Camera,
    CameraFrame,
    CameraIntrinsics,
    Clock,
    Goal,
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
    Pose2D,
)
from mmexec.sim.clearance import ClearanceMap
from mmexec.sim.faults import FaultInjector
from mmexec.sim.models import ModelInfo
from mmexec.sim.people import SimPeople
from mmexec.sim.raycast import SceneRays
from mmexec.sim.scene import SceneHandles

__all__ = ["Contact", "SimArm", "SimBase", "SimCamera", "SimClock", "SimCore", "SimGripper", "SimHead", "SimLidar"]

log = logging.getLogger(__name__)

#: Default ``SimCore.true_pose`` (immutable, so one shared instance is fine).
_ORIGIN = Pose2D()


class SimClock(Clock):
    """Simulation time: ``steps / physics_hz`` seconds, advanced only by the backend."""

    stepped = True

    def __init__(self, physics_hz: int) -> None:
        self.hz = physics_hz
        self.steps = 0

    def now(self) -> float:
        return self.steps / self.hz


def _mat(pos: Sequence[float], quat: Sequence[float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
    T[:3, 3] = pos
    return T


@dataclass(frozen=True)
class Contact:
    """A contact of the robot with another body (ground truth, sim-only): clock time
    ``t`` [s], the robot ``part`` (``base``: a move the bumper refused; ``arm``: an arm
    or gripper link touching static geometry or a person in a physics step), the other
    ``body`` (a static part's name, e.g. ``shelf_far_side_l``, ``clutter_2``, or a
    person's), and the base's true ``pose`` in ``map`` [m, m, rad]."""

    t: float
    part: str
    body: str
    pose: Pose2D


@dataclass
class SimCore:
    """State shared by the capabilities of one simulated robot. ``people``: the world's
    walking people (None: there are none); ``contacts``: every contact so far (ground
    truth for measurement, never for skills)."""

    cid: int
    body: int
    info: ModelInfo
    clock: SimClock
    rng: np.random.Generator
    faults: FaultInjector
    scene: SceneHandles
    links: dict[str, int] = field(default_factory=dict)
    joints: dict[str, int] = field(default_factory=dict)
    true_pose: Pose2D = _ORIGIN
    held_body: int | None = None
    clearance: ClearanceMap | None = None  #: static-geometry clearance for the base (set by the backend)
    people: SimPeople | None = None
    contacts: list[Contact] = field(default_factory=list)
    #: every grasp so far: (clock time [s], item, the item's link indices the pads touch;
    #: -1 the base link): ground truth of which part of an object the fingers hold
    grasps: list[tuple[float, str, tuple[int, ...]]] = field(default_factory=list)
    #: sim-only teleports so far (place_base, arm/gripper/head set-ups): with the clock's
    #: step count it tells a sensor that nothing moved since its last reading
    teleports: int = 0
    _placed: Pose2D | None = field(default=None, repr=False)

    def sync(self) -> None:
        """Put the pybullet body at ``true_pose`` if the base moved since it was last
        placed. The base integrates its pose every substep but places the body lazily:
        before a physics step, an exact collision test, a render or a link query."""
        if self._placed != self.true_pose:
            pose = self.true_pose
            q = p.getQuaternionFromEuler((0.0, 0.0, pose.theta))
            p.resetBasePositionAndOrientation(self.body, (pose.x, pose.y, 0.0), q, physicsClientId=self.cid)
            if self.held_body is not None and self._placed is not None:
                # The base is placed kinematically, so the solver never sees its velocity: a
                # held item would only be dragged after the tool by the force-limited grasp
                # constraint, lagging ~v*dt/ERP (2 cm at 0.2 m/s) and counted as dropped.
                # A gripper carries what it holds with the base: move it by the same step.
                step = pose.matrix() @ np.linalg.inv(self._placed.matrix())
                ipos, iorn = p.getBasePositionAndOrientation(self.held_body, physicsClientId=self.cid)
                T = step @ _mat(ipos, iorn)
                p.resetBasePositionAndOrientation(self.held_body, *position_quat(T), physicsClientId=self.cid)
            if self.scene.plants is not None:  # the basket on the robot, and the fruit in it
                self.scene.plants.carry(pose.matrix(), self.held_body)
            self._placed = pose

    def link_T(self, name: str) -> np.ndarray:
        """``T_world_link`` of a model link (world = ``map``)."""
        self.sync()
        s = p.getLinkState(self.body, self.links[name], computeForwardKinematics=True, physicsClientId=self.cid)
        return _mat(s[4], s[5])

    def base_T(self) -> np.ndarray:
        """``T_map_base`` of the true base pose."""
        return self.true_pose.matrix()

    def in_base(self, name: str) -> np.ndarray:
        """``T_base_link`` of a model link."""
        return np.linalg.inv(self.base_T()) @ self.link_T(name)

    def place_base(self, pose: Pose2D) -> None:
        """Sim-only: teleport the base (true pose in ``map``) and place the body now."""
        self.teleports += 1
        self.true_pose = pose
        self.sync()


# --------------------------------------------------------------------------- base


@dataclass(frozen=True)
class OdometryNoise:
    """How the odometry drifts from the true motion.

    Per substep (random, n ~ N(0, 1) each): the measured distance is ``ds * (1 + linear *
    n1)`` and the measured turn ``dth + |dth| * angular * n2 + |ds| * 0.1 * angular * n3``.

    Systematic (all 0 by default; the ``realistic`` profile of :data:`ODOMETRY_PROFILES`
    sets them), each drawn once per run as ``N(0, value)``:

    * ``scale``: wheel-radius error, the measured distance is ``(1 + e_scale)`` times the
      true one [fraction];
    * ``gyro_scale``: gyro scale error, the measured turn is ``(1 + e_gyro)`` times the
      true one [fraction] (the Kobuki's heading comes from its gyro);
    * ``gyro_bias``: a constant yaw-rate bias [rad/s], integrated while the base moves (at
      rest the sim's base is not integrated, as an odometry that holds still when the
      wheels do);

    and ``slip`` [s^2/m]: wheel slip under acceleration, ``ds * slip * a * |n4|`` added
    to the measured distance, ``a`` [m/s^2] the acceleration along the motion (speeding
    up: the wheels spin ahead of the ground; braking: they lag behind it)."""

    linear: float = 0.01
    angular: float = 0.02
    scale: float = 0.0
    gyro_scale: float = 0.0
    gyro_bias: float = 0.0
    slip: float = 0.0

    def validate(self) -> list[str]:
        bad = [f.name for f in fields(self) if not getattr(self, f.name) >= 0]
        return [f"odometry noise {', '.join(bad)} must be >= 0"] if bad else []

    @property
    def systematic(self) -> bool:
        """True when any per-run error or slip is on (draws from the generator at build)."""
        return bool(self.scale or self.gyro_scale or self.gyro_bias or self.slip)


#: Named odometry-noise profiles (``sim.odometry_noise.profile``). ``realistic`` is a
#: Kobuki-class base on an indoor floor: 2 % wheel-radius error (tyre wear and load,
#: floor), 1 % gyro scale error, 0.06 deg/s gyro bias (a MEMS gyro after its power-on
#: calibration), slip under acceleration, on top of the default random terms (see
#: docs/localization.md).
ODOMETRY_PROFILES: dict[str, OdometryNoise] = {
    "default": OdometryNoise(),
    "realistic": OdometryNoise(linear=0.01, angular=0.02, scale=0.02, gyro_scale=0.01, gyro_bias=0.001, slip=0.1),
}


class SimBase(Base):
    """Kinematic differential drive with limits, a 0.6 s watchdog, bumper stop and
    drifting odometry. ``state().pose`` is the odometry estimate in ``map`` (starting at
    the true start pose); the truth is on ``SimRobot.truth``."""

    def __init__(self, core: SimCore, noise: OdometryNoise, bump_links: tuple[str, ...]) -> None:
        self._c = core
        self._noise = noise
        self.max_linear = core.info.max_linear
        self.max_angular = core.info.max_angular
        self.radius = core.info.footprint_radius
        self._cmd = (0.0, 0.0)
        self._cmd_time = -math.inf
        self._v = 0.0
        self._w = 0.0
        self._est = core.true_pose
        # per-run systematic odometry errors (drawn only when the profile has them, so a
        # config without them draws nothing and reproduces its runs)
        self._scale, self._gyro_scale, self._gyro_bias = 1.0, 1.0, 0.0
        if noise.systematic:
            e = core.rng.standard_normal(3)
            self._scale = 1.0 + noise.scale * float(e[0])
            self._gyro_scale = 1.0 + noise.gyro_scale * float(e[1])
            self._gyro_bias = noise.gyro_bias * float(e[2])
        self._faults: frozenset[str] = frozenset()
        self._bump_links = tuple(core.links[n] for n in bump_links)
        self.bumps = 0  #: number of substeps refused for collision (for tests and scoring)
        self._touching = ""  # the body the last refused move touched ("" after a move)
        self.exact_checks = 0  #: substeps that needed the exact getClosestPoints test (benchmarks)
        # disk around the base origin holding the bumper bodies at any yaw, and their heights
        core.sync()
        o = np.array([core.true_pose.x, core.true_pose.y])
        r, zlo, zhi = 0.0, math.inf, -math.inf
        for li in self._bump_links:
            lo, hi = p.getAABB(core.body, li, physicsClientId=core.cid)
            for cx in (lo[0], hi[0]):
                for cy in (lo[1], hi[1]):
                    r = max(r, float(np.hypot(cx - o[0], cy - o[1])))
            zlo, zhi = min(zlo, lo[2]), max(zhi, hi[2])
        self.bump_radius = r  #: [m] horizontal radius holding the bumper bodies
        self.bump_heights = (zlo, zhi)  #: [m] height range of the bumper bodies

    def still(self) -> bool:
        """True when the base is at rest and no live command will move it."""
        live = self._c.clock.now() - self._cmd_time <= self.command_timeout and self._cmd != (0.0, 0.0)
        return self._v == 0.0 and self._w == 0.0 and not live

    def state(self) -> BaseState:
        return BaseState(pose=self._est, v=self._v, w=self._w, stamp=self._c.clock.now(), faults=self._faults)

    def set_velocity(self, v: float, w: float) -> None:
        if not (math.isfinite(v) and math.isfinite(w)):
            raise ValueError(f"base velocity must be finite, got v={v}, w={w}")
        self._cmd = (max(-self.max_linear, min(self.max_linear, v)), max(-self.max_angular, min(self.max_angular, w)))
        self._cmd_time = self._c.clock.now()

    def reset_estimate(self, pose: Pose2D) -> None:
        """Sim-only: set the odometry estimate (as a localisation fix would)."""
        self._est = pose

    def _collides(self) -> tuple[bool, float, str]:
        """Whether the base body intersects static geometry, the contact bearing [rad] and
        the static part's name."""
        c = self._c
        for li in self._bump_links:
            for pt in p.getClosestPoints(c.body, c.scene.static, 0.0, linkIndexA=li, physicsClientId=c.cid):
                if pt[8] < -1e-4:
                    d = np.array(pt[5]) - np.array([c.true_pose.x, c.true_pose.y, 0.0])
                    names = c.scene.static_names
                    name = names[pt[4]] if 0 <= pt[4] < len(names) else "static"
                    return True, wrap_angle(math.atan2(d[1], d[0]) - c.true_pose.theta), name
        return False, 0.0, ""

    def _touches_person(self, pose: Pose2D) -> tuple[bool, float, str]:
        """Whether the base body at ``pose`` (already placed) intersects a person: a
        footprint-disk test first, the exact one for the people it cannot rule out."""
        c = self._c
        people = c.people
        if people is None or not len(people):
            return False, 0.0, ""
        near = np.flatnonzero(people.gaps(pose.x, pose.y, self.bump_radius) < 0.0)
        if near.size:
            c.sync()
        for k in near:
            for li in self._bump_links:
                for pt in p.getClosestPoints(c.body, people.bodies[k], 0.0, linkIndexA=li, physicsClientId=c.cid):
                    if pt[8] < -1e-4:
                        d = np.array(pt[5]) - np.array([pose.x, pose.y, 0.0])
                        return True, wrap_angle(math.atan2(d[1], d[0]) - pose.theta), people.names[k]
        return False, 0.0, ""

    def update(self, dt: float) -> None:
        now = self._c.clock.now()
        tv, tw = self._cmd if now - self._cmd_time <= self.command_timeout else (0.0, 0.0)
        if self._faults & {"bumper_left", "bumper_centre", "bumper_right"} and tv > 0:
            tv = 0.0 if self._v >= 0 else tv
        dv, dw = self.max_linear_accel * dt, self.max_angular_accel * dt
        v_before = self._v
        self._v += max(-dv, min(dv, tv - self._v))
        self._w += max(-dw, min(dw, tw - self._w))
        if self._v == 0.0 and self._w == 0.0:
            return
        c = self._c
        old = c.true_pose
        th = old.theta + self._w * dt / 2
        new = Pose2D(old.x + self._v * dt * math.cos(th), old.y + self._v * dt * math.sin(th), wrap_angle(old.theta + self._w * dt))
        c.true_pose = new  # the body follows lazily (SimCore.sync)
        hit, ang, what = False, 0.0, ""
        if c.clearance is None or not c.clearance.clear(new.x, new.y, self.bump_radius):
            self.exact_checks += 1
            c.sync()
            hit, ang, what = self._collides()
        if not hit:
            hit, ang, what = self._touches_person(new)
        if hit:
            c.place_base(old)
            side = "bumper_left" if ang > 0.35 else "bumper_right" if ang < -0.35 else "bumper_centre"
            self._faults = frozenset({side})
            self._v = self._w = 0.0
            self.bumps += 1
            if what != self._touching:  # one contact per body until the base moves again
                c.contacts.append(Contact(now, "base", what, old))
                self._touching = what
            return
        self._faults = frozenset()
        self._touching = ""
        # odometry: integrate the measured increments with multiplicative noise
        ds, dth = self._v * dt, self._w * dt
        n = self._noise
        ds_m = ds * (1.0 + n.linear * c.rng.standard_normal()) if n.linear else ds
        dth_m = dth + abs(dth) * n.angular * c.rng.standard_normal() + abs(ds) * n.angular * 0.1 * c.rng.standard_normal() if n.angular else dth
        if n.systematic:
            along = (self._v - v_before) / dt * (1.0 if self._v >= 0 else -1.0)  # [m/s^2], > 0 speeding up
            ds_m = ds_m * self._scale + (ds * n.slip * along * abs(c.rng.standard_normal()) if n.slip else 0.0)
            dth_m = dth_m * self._gyro_scale + self._gyro_bias * dt
        e = self._est
        eth = e.theta + dth_m / 2
        self._est = Pose2D(e.x + ds_m * math.cos(eth), e.y + ds_m * math.sin(eth), wrap_angle(e.theta + dth_m))


# --------------------------------------------------------------------------- arm


class SimArm(Arm):
    """Position-controlled joints following a :class:`JointTrajectory` sampled every
    substep. Checks range and velocity limits before moving; succeeds when the last
    waypoint is reached within ``tolerance`` [rad]; fails when it is not reached
    ``settle_time`` after the trajectory's end (blocked by a collision) or on an
    injected fault. Cancel ramps the velocity to zero over ``stop_time`` seconds."""

    tolerance = 0.01
    settle_time = 1.5
    stop_time = 0.15

    def __init__(self, core: SimCore) -> None:
        self._c = core
        self._idx = [core.joints[n] for n in core.info.arm_joints]
        lims = []
        for n, i in zip(core.info.arm_joints, self._idx):
            ji = p.getJointInfo(core.body, i, physicsClientId=core.cid)
            lower, upper = (ji[8], ji[9]) if ji[8] <= ji[9] else (-math.inf, math.inf)  # continuous: 0 > -1
            lims.append(JointLimit(n, lower, upper, ji[11], effort=ji[10]))
        self._limits = tuple(lims)
        self._goal: Goal | None = None
        self._traj: JointTrajectory | None = None
        self._start_q: tuple[float, ...] = ()
        self._t0 = 0.0
        self._fail_at: float | None = None
        self._stop: tuple[float, np.ndarray, np.ndarray] | None = None
        self._hold: np.ndarray | None = None
        self._held_cmd: np.ndarray | None = None
        self.attempts = 0

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._c.info.arm_joints

    @property
    def limits(self) -> tuple[JointLimit, ...]:
        return self._limits

    @property
    def mount(self) -> np.ndarray:
        return self._c.in_base(self._c.info.arm_base_link)

    def _q(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        st = p.getJointStates(self._c.body, self._idx, physicsClientId=self._c.cid)
        return (np.array([s[0] for s in st]), np.array([s[1] for s in st]), np.array([s[3] for s in st]))

    def state(self) -> JointState:
        q, dq, eff = self._q()
        return JointState(self.joint_names, tuple(q.tolist()), tuple(dq.tolist()), tuple(eff.tolist()), self._c.clock.now())

    def set_positions(self, q: Sequence[float]) -> None:
        """Sim-only: teleport the arm (setup and tests), holding there."""
        self._c.teleports += 1
        for i, v in zip(self._idx, q):
            p.resetJointState(self._c.body, i, float(v), 0.0, physicsClientId=self._c.cid)
        self._hold = np.array(q, dtype=float)

    def _check(self, traj: JointTrajectory, q0: np.ndarray) -> str:
        if tuple(traj.joint_names) != self.joint_names:
            return f"trajectory joints {list(traj.joint_names)} differ from the arm's {list(self.joint_names)}"
        prev_t, prev = 0.0, q0
        for t, wp in zip(traj.times, traj.positions):
            for lim, v in zip(self._limits, wp):
                if not math.isfinite(v) or not lim.contains(v, 1e-6):
                    return f"joint {lim.name}: target {v:.4f} outside limits [{lim.lower:.4f}, {lim.upper:.4f}] at t={t:.3f} s"
            seg = np.array(wp) - prev
            for lim, d in zip(self._limits, seg):
                vel = abs(d) / (t - prev_t)
                if vel > lim.velocity * (1 + 1e-6):
                    return f"joint {lim.name}: velocity {vel:.3f} rad/s above limit {lim.velocity:.3f} before t={t:.3f} s"
            prev_t, prev = t, np.array(wp)
        return ""

    def follow(self, trajectory: JointTrajectory) -> Goal:
        if self._goal is not None and not self._goal.done():
            self._goal.fail("preempted by a new trajectory")
        q0, _, _ = self._q()
        problem = self._check(trajectory, q0)
        if problem:
            return Goal.failed("arm.follow", problem)
        now = self._c.clock.now()
        self.attempts += 1
        goal = Goal("arm.follow", on_cancel=self._on_cancel)
        self._goal, self._traj, self._start_q, self._t0 = goal, trajectory, tuple(q0.tolist()), now
        self._stop = None
        self._fail_at = now + trajectory.duration / 2 if self._c.faults.arm_attempt_fails(now) else None
        return goal

    def _on_cancel(self, goal: Goal) -> None:
        q, dq, _ = self._q()
        self._stop = (self._c.clock.now(), q, dq)
        self._traj = None

    def stop(self) -> None:
        if self._goal is not None and not self._goal.done():
            self._goal.cancel()
        elif self._stop is None:
            self._hold = self._q()[0]

    def at_rest(self) -> bool:
        """True when no goal or stop ramp is active, the hold target is commanded and
        every joint moves slower than 1e-3 rad/s (physics may pause, see SimRobot.spin)."""
        if (self._goal is not None and not self._goal.done()) or self._stop is not None or self._traj is not None:
            return False
        if self._hold is None or self._held_cmd is not self._hold:
            return False
        return bool(np.all(np.abs(self._q()[1]) < 1e-3))

    def _sample(self, t: float) -> np.ndarray:
        traj = self._traj
        assert traj is not None
        if t < traj.times[0]:
            a = t / traj.times[0]
            return np.array(self._start_q) + a * (np.array(traj.positions[0]) - np.array(self._start_q))
        return np.array(traj.sample(t))

    def _command(self, target: np.ndarray) -> None:
        c = self._c
        p.setJointMotorControlArray(c.body, self._idx, p.POSITION_CONTROL, targetPositions=target.tolist(),
                                    forces=[max(50.0, 5 * lim.effort) for lim in self._limits],
                                    positionGains=[0.5] * len(self._idx), physicsClientId=c.cid)

    def update(self, dt: float) -> None:
        now = self._c.clock.now() + dt
        goal = self._goal
        if self._stop is not None:
            t0, q, dq = self._stop
            s = min(now - t0, self.stop_time)
            target = q + dq * (s - s * s / (2 * self.stop_time))
            self._command(target)
            if now - t0 >= self.stop_time:
                self._hold, self._stop = target, None
                if goal is not None:
                    goal.mark_cancelled("cancelled: arm stopped and holding")
            return
        if goal is None or goal.done() or self._traj is None:
            if self._hold is None:
                self._hold = self._q()[0]
            if self._held_cmd is not self._hold:  # motor targets persist: command once
                self._command(self._hold)
                self._held_cmd = self._hold
            return
        self._held_cmd = None
        t = now - self._t0
        if self._fail_at is not None and now >= self._fail_at:
            q = self._q()[0]
            self._hold, self._traj = q, None
            self._command(q)
            goal.fail(f"arm motion failed at t={t:.2f} s (injected fault, attempt {self.attempts})")
            return
        self._command(self._sample(t))
        if t >= self._traj.duration:
            q = self._q()[0]
            err = np.abs(q - np.array(self._traj.positions[-1]))
            if float(err.max()) <= self.tolerance:
                self._hold, self._traj = np.array(self._traj.positions[-1]), None
                goal.succeed(self.state())
            elif t >= self._traj.duration + self.settle_time:
                j = int(np.argmax(err))
                self._hold, self._traj = q, None
                goal.fail(f"joint {self.joint_names[j]}: {err[j]:.3f} rad short of the goal {self.settle_time} s "
                          f"after the trajectory ended (blocked?)")


# --------------------------------------------------------------------------- gripper


class SimGripper(Gripper):
    """Two prismatic pads under position control with a force limit.

    A move succeeds when the pads stop: at the width (``AT_POSITION``) or early while
    closing with contact on both pads (``CONTACT_CLOSING``). Stopped means stalled: the
    width has changed by less than ``stall_progress`` [m] over the last ``stall_window``
    [s of sim time] while the commanded width runs ahead of the pads (or has reached the
    target). Pads pressing on an item jitter at a few mm/s, so their speed is no test. An item is held only then:
    a fixed constraint to the tool frame carries it, with a strength from the friction
    the pads can produce (``mu * force``). Grasped off-centre (item centre more than
    ``slip_offset`` from the pad centre along the fingers) the hold is weaker than the
    item's weight, so it slides out and is dropped (``DROPPED``). Opening releases it.
    """

    friction = 0.8
    slip_offset = 0.02  # m
    stall_window = 0.1  # s of sim time
    stall_progress = 5e-4  # m of width change within stall_window

    def __init__(self, core: SimCore) -> None:
        self._c = core
        info = core.info
        self.min_width, self.max_width = info.gripper_width_range
        self.max_force = info.gripper_force
        self._idx = [core.joints[n] for n in info.gripper_joints]
        self._pads = [core.links[n] for n in info.finger_links]
        self._goal: Goal | None = None
        self._target = self.max_width
        self._cmd = self.max_width
        self._speed = info.gripper_speed
        self._force = self.max_force
        self._closing = False
        self._widths: deque[tuple[float, float]] = deque()  # (sim time [s], width [m]) of this move
        self._grasp = GraspState.AT_POSITION
        self.held: str | None = None
        self._cons: int | None = None
        self._held_since = 0.0
        self._slip_after: float | None = None
        self._hold_T: np.ndarray | None = None

    def at_rest(self) -> bool:
        """True when nothing is held and no move is in progress (the pad targets persist)."""
        return self.held is None and (self._goal is None or self._goal.done()) and self._cmd == self._target

    def _width(self) -> float:
        st = p.getJointStates(self._c.body, self._idx, physicsClientId=self._c.cid)
        return self._c.info.q_to_width(st[0][0], st[1][0])

    def state(self) -> GripperState:
        return GripperState(self._width(), self._grasp, self._c.clock.now())

    def set_width(self, width: float) -> None:
        """Sim-only: teleport the pads (setup and tests)."""
        self._c.teleports += 1
        for i, q in zip(self._idx, self._c.info.width_to_q(width)):
            p.resetJointState(self._c.body, i, q, 0.0, physicsClientId=self._c.cid)
        self._cmd = self._target = width

    def move(self, width: float, *, speed: float = 0.1, force: float = 50.0) -> Goal:
        if not (self.min_width - 1e-6 <= width <= self.max_width + 1e-6):
            return Goal.failed("gripper.move", f"width {width:.4f} m outside [{self.min_width}, {self.max_width}] m")
        if speed <= 0 or force <= 0:
            return Goal.failed("gripper.move", f"speed and force must be > 0 (got {speed}, {force})")
        if self._goal is not None and not self._goal.done():
            self._goal.fail("preempted by a new gripper move")
        cur = self._width()
        self._closing = width < cur
        if not self._closing:
            self._release(GraspState.MOVING)
        self._target = width
        self._cmd = cur
        self._speed = min(speed, self._c.info.gripper_speed)
        self._force = min(force, self.max_force)
        self._widths.clear()
        self._grasp = GraspState.MOVING
        self._goal = Goal("gripper.move", on_cancel=self._on_cancel)
        return self._goal

    def _on_cancel(self, goal: Goal) -> None:
        self._target = self._cmd = self._width()
        self._grasp = GraspState.AT_POSITION
        goal.mark_cancelled("cancelled: fingers stopped")

    def _release(self, state: GraspState) -> None:
        if self._cons is not None:
            p.removeConstraint(self._cons, physicsClientId=self._c.cid)
            self._cons = None
            if self._c.held_body is not None:  # free again: may fall asleep once at rest
                p.changeDynamics(self._c.held_body, -1, activationState=p.ACTIVATION_STATE_ENABLE_SLEEPING,
                                 physicsClientId=self._c.cid)
        self.held = None
        self._c.held_body = None
        self._grasp = state

    def _contacts(self) -> list[set[int]]:
        c = self._c
        out = []
        for li in self._pads:
            bodies = {pt[2] for pt in p.getContactPoints(bodyA=c.body, linkIndexA=li, physicsClientId=c.cid)
                      if pt[2] != c.body and pt[8] < 0.002}
            out.append(bodies)
        return out

    def _grab(self, name: str, body: int) -> None:
        c = self._c
        tool = c.links[c.info.tool_link]
        T_tool = c.link_T(c.info.tool_link)
        pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=c.cid)
        T_item = _mat(pos, orn)
        rel = np.linalg.inv(T_tool) @ T_item
        mass = p.getDynamicsInfo(body, -1, physicsClientId=c.cid)[0]
        # a held item must follow the arm: awake, and never put to sleep while held
        p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_WAKE_UP, physicsClientId=c.cid)
        p.changeDynamics(body, -1, activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=c.cid)
        # offset from the pad centre along the fingers: the Interbotix tool frame sits at
        # the pads (its x runs along them); the Robotiq's tool link is the flange (tool0),
        # so its pads' centre lies along tool z, measured from the pad links themselves
        if c.info.gripper_mode == "interbotix":
            along = abs(rel[0, 3])
        else:
            pads_z = [float((np.linalg.inv(T_tool) @ c.link_T(n))[2, 3]) for n in c.info.finger_links]
            along = abs(rel[2, 3] - sum(pads_z) / len(pads_z))
        hold = self.friction * self._force
        if along > self.slip_offset:
            hold = 0.3 * mass * 9.81
        pos7, quat7 = position_quat(rel)
        self._cons = p.createConstraint(c.body, tool, body, -1, p.JOINT_FIXED, [0, 0, 0], pos7, [0, 0, 0],
                                        parentFrameOrientation=quat7, physicsClientId=c.cid)
        p.changeConstraint(self._cons, maxForce=hold, physicsClientId=c.cid)
        self.held = name
        c.held_body = body
        self._hold_T = rel
        touched = {pt[4] for li in self._pads for pt in p.getContactPoints(bodyA=c.body, bodyB=body, linkIndexA=li,
                                                                          physicsClientId=c.cid) if pt[8] < 0.002}
        c.grasps.append((c.clock.now(), name, tuple(sorted(touched))))
        self._held_since = c.clock.now()
        self._slip_after = c.faults.slip_after(name)

    def update(self, dt: float) -> None:
        c = self._c
        if self.held is None and (self._goal is None or self._goal.done()) and self._cmd == self._target:
            return  # idle: the motor targets set last time persist
        step = self._speed * dt
        self._cmd = self._cmd + max(-step, min(step, self._target - self._cmd))
        qs = c.info.width_to_q(self._cmd if not self.held else self._target)
        p.setJointMotorControlArray(c.body, self._idx, p.POSITION_CONTROL, targetPositions=list(qs),
                                    forces=[self._force / 2] * 2, positionGains=[0.5, 0.5], physicsClientId=c.cid)
        if self.held is not None:
            self._check_hold()
        goal = self._goal
        if goal is None or goal.done():
            return
        st = p.getJointStates(c.body, self._idx, physicsClientId=c.cid)
        moving = abs(st[0][1]) + abs(st[1][1]) > 1e-3
        width = c.info.q_to_width(st[0][0], st[1][0])
        at_cmd_end = abs(self._cmd - self._target) < 1e-9
        if abs(width - self._target) < 1e-3 and at_cmd_end and not moving:
            self._grasp = GraspState.AT_POSITION
            goal.succeed(self.state())
            return
        if not self._stalled(c.clock.now(), width):
            return
        if self._closing and width > self._target + 1e-3 and (at_cmd_end or self._cmd < width - 2e-3):
            left, right = self._contacts()
            both = left & right
            item = next((n for n, b in c.scene.items.items() if b in both), None)
            if item is not None:
                self._target = self._cmd = max(self.min_width, width - 0.004)  # keep squeezing
                self._grab(item, c.scene.items[item])
                self._grasp = GraspState.CONTACT_CLOSING
            else:
                self._grasp = GraspState.AT_POSITION
                self._target = self._cmd = width
            goal.succeed(self.state())
        elif not self._closing and at_cmd_end:
            self._grasp = GraspState.AT_POSITION
            goal.succeed(self.state())

    def _stalled(self, now: float, width: float) -> bool:
        """Record the width [m] at sim time ``now`` [s]; True once the record spans
        ``stall_window`` (and at least 3 steps) and the width moved less than
        ``stall_progress`` over it."""
        w = self._widths
        w.append((now, width))
        while len(w) > 3 and now - w[1][0] >= self.stall_window:
            w.popleft()
        if len(w) < 3 or now - w[0][0] < self.stall_window - 1e-9:
            return False
        lo = min(x for _, x in w)
        hi = max(x for _, x in w)
        return hi - lo < self.stall_progress

    def _check_hold(self) -> None:
        c = self._c
        name = self.held
        assert name is not None
        body = c.scene.items[name]
        now = c.clock.now()
        if self._slip_after is not None and now - self._held_since >= self._slip_after:
            c.faults.fired.append((now, f"grasp_slip {name}"))
            self._release(GraspState.DROPPED)
            return
        T_tool = c.link_T(c.info.tool_link)  # first: placing the base moves the held item too
        pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=c.cid)
        rel = np.linalg.inv(T_tool) @ _mat(pos, orn)
        assert self._hold_T is not None
        if np.linalg.norm(rel[:3, 3] - self._hold_T[:3, 3]) > 0.015:
            self._release(GraspState.DROPPED)


# --------------------------------------------------------------------------- head


def _teleport_head(core: SimCore, pan: float, tilt: float) -> tuple[float, float]:
    """Put the pan/tilt joints at ``pan``, ``tilt`` [rad] (clipped to their limits) and
    hold them there with their motors; returns the clipped pose."""
    core.teleports += 1
    out = []
    for name, v in zip(core.info.pan_tilt_joints, (pan, tilt)):
        j = core.joints[name]
        lo, hi = p.getJointInfo(core.body, j, physicsClientId=core.cid)[8:10]
        q = min(hi, max(lo, v))
        p.resetJointState(core.body, j, q, physicsClientId=core.cid)
        p.setJointMotorControl2(core.body, j, p.POSITION_CONTROL, targetPosition=q, force=2.0,
                                physicsClientId=core.cid)
        out.append(q)
    return out[0], out[1]


class SimHead(Head):
    """The pan/tilt head on the model's ``pan_tilt_joints``: position-controlled motors
    (force: the joints' effort limit, position gain 0.5 as the arm's: a 1 rad move settles
    in 0.45 s, the servo's profile takes 0.35 s) whose set-points ramp towards the target at the
    joints' velocity limit every substep, as a servo's velocity profile does. Targets
    outside the URDF limits fail at once (nothing moves); the goal succeeds once the
    set-point is at the target and both measured joints are within :attr:`tolerance`
    and slower than :attr:`settled_speed`, and fails ``settle_time`` [s] after the ramp's end if they are not (blocked). Cancel
    holds the measured pose at once (the head is light). Idle, the head is not commanded
    at all: the motors keep the last target (the start pose of ``sim.camera.pan/tilt``)."""

    settle_time = 1.0
    settled_speed = 0.05  #: rad/s: both joints slower than this count as arrived

    def __init__(self, core: SimCore, home: tuple[float, float], kinematics: object | None = None) -> None:
        self._c = core
        names = core.info.pan_tilt_joints
        self._names: tuple[str, str] = (names[0], names[1])
        self._idx = [core.joints[n] for n in names]
        lims = []
        for n, i in zip(names, self._idx):
            ji = p.getJointInfo(core.body, i, physicsClientId=core.cid)
            lims.append(JointLimit(n, ji[8], ji[9], ji[11], effort=ji[10]))
        self._limits: tuple[JointLimit, JointLimit] = (lims[0], lims[1])
        self._home = home
        self._kinematics = kinematics
        self._goal: Goal | None = None
        self._target = np.zeros(2)
        self._cmd = np.zeros(2)
        self._deadline = 0.0
        self.moves = 0  #: point() goals started (tests)

    @property
    def joint_names(self) -> tuple[str, str]:
        return self._names

    @property
    def limits(self) -> tuple[JointLimit, JointLimit]:
        return self._limits

    @property
    def home(self) -> tuple[float, float]:
        return self._home

    @property
    def kinematics(self) -> object | None:
        return self._kinematics

    def _q(self) -> tuple[np.ndarray, np.ndarray]:
        st = p.getJointStates(self._c.body, self._idx, physicsClientId=self._c.cid)
        return np.array([s[0] for s in st]), np.array([s[1] for s in st])

    def state(self) -> HeadState:
        q, dq = self._q()
        return HeadState(float(q[0]), float(q[1]), self._c.clock.now(), float(dq[0]), float(dq[1]))

    def teleport(self, pan: float, tilt: float) -> None:
        """Sim-only: put the head at ``pan``, ``tilt`` [rad] at once (clipped), holding."""
        if self._goal is not None and not self._goal.done():
            self._goal.mark_cancelled("head teleported")
        self._goal = None
        self._target = self._cmd = np.array(_teleport_head(self._c, pan, tilt))

    def point(self, pan: float, tilt: float) -> Goal:
        problem = self.limit_problem(pan, tilt)
        if problem:
            return Goal.failed("head.point", problem)
        if self._goal is not None and not self._goal.done():
            self._goal.mark_cancelled("preempted by a new head goal")
        q, _ = self._q()
        target = np.array([float(pan), float(tilt)])
        ramp = max(float(abs(t - a)) / lim.velocity for t, a, lim in zip(target, q, self._limits))
        self.moves += 1
        self._goal = Goal("head.point", on_cancel=self._on_cancel)
        self._target, self._cmd = target, q
        self._deadline = self._c.clock.now() + ramp + self.settle_time
        return self._goal

    def _command(self, q: np.ndarray) -> None:
        c = self._c
        p.setJointMotorControlArray(c.body, self._idx, p.POSITION_CONTROL, targetPositions=q.tolist(),
                                    forces=[lim.effort for lim in self._limits], positionGains=[0.5, 0.5],
                                    physicsClientId=c.cid)

    def _on_cancel(self, goal: Goal) -> None:
        q, _ = self._q()
        self._target = self._cmd = q
        self._command(q)
        goal.mark_cancelled("cancelled: head holding")

    def stop(self) -> None:
        if self._goal is not None and not self._goal.done():
            self._goal.cancel()

    def at_rest(self) -> bool:
        """True when no head goal is running (the motors hold their last target)."""
        return self._goal is None or self._goal.done()

    def update(self, dt: float) -> None:
        goal = self._goal
        if goal is None or goal.done():
            return
        step = np.array([lim.velocity * dt for lim in self._limits])
        self._cmd = self._cmd + np.clip(self._target - self._cmd, -step, step)
        self._command(self._cmd)
        q, dq = self._q()
        err = np.abs(q - self._target)
        settled = float(np.abs(dq).max()) < self.settled_speed
        if np.array_equal(self._cmd, self._target) and float(err.max()) <= self.tolerance and settled:
            goal.succeed(self.state())
        elif self._c.clock.now() + dt > self._deadline:
            j = int(np.argmax(err))
            self._target = self._cmd = q
            self._command(q)
            goal.fail(f"head joint {self._names[j]}: {err[j]:.3f} rad short of the target {self.settle_time:g} s "
                      "after the move should have ended (blocked?)")


# --------------------------------------------------------------------------- sensors


@dataclass(frozen=True)
class CameraNoise:
    """Gaussian noise: ``rgb`` std [intensity levels 0-255]; ``depth`` std [m] at 1 m,
    growing with the square of the distance (stereo-like)."""

    rgb: float = 0.0
    depth: float = 0.0


class SimCamera(Camera):
    """RGB-D camera rendered on demand with TinyRenderer (shadows off).

    ``mount``: an extra ``T_link_optical`` correction applied to the model's optical
    frame (wrist camera mount offset from the config); None = as modelled."""

    def __init__(self, core: SimCore, intr: CameraIntrinsics, near: float, far: float, noise: CameraNoise,
                 base: SimBase | None, mount: np.ndarray | None = None) -> None:
        self._c = core
        self._intr = intr
        self.near, self.far = near, far
        self._noise = noise
        self._base = base
        self._mount = mount if mount is not None else np.eye(4)
        vfov = 2 * math.degrees(math.atan((intr.height / 2) / intr.fy))
        self._proj = p.computeProjectionMatrixFOV(vfov, intr.width / intr.height, near, far, physicsClientId=core.cid)
        self.frames = 0  #: rendered frame count (benchmarks)

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._intr

    def pose_in_base(self) -> np.ndarray:
        return self._c.in_base(self._c.info.camera_optical_link) @ self._mount

    def set_pan_tilt(self, pan: float, tilt: float) -> None:
        """Sim-only (LoCoBot): point the pan/tilt head [rad] (teleported, within limits)."""
        _teleport_head(self._c, pan, tilt)

    def render(self, T_map_opt: np.ndarray, width: int, height: int, proj: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """RGB (HxWx3 uint8) and z-buffer (HxW float) seen from an optical frame pose."""
        T_gl = T_map_opt @ np.diag([1.0, -1.0, -1.0, 1.0])
        view = np.linalg.inv(T_gl).T.reshape(-1).tolist()
        _, _, rgba, zbuf, _ = p.getCameraImage(width, height, view, proj, renderer=p.ER_TINY_RENDERER, shadow=0,
                                               flags=p.ER_NO_SEGMENTATION_MASK, physicsClientId=self._c.cid)
        rgb = cv2.cvtColor(np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4), cv2.COLOR_RGBA2RGB)
        return rgb, np.asarray(zbuf, dtype=np.float32).reshape(height, width)

    def frame(self) -> CameraFrame | None:
        c = self._c
        now = c.clock.now()
        if c.faults.camera_dropped(now):
            return None
        T_base_cam = self.pose_in_base()
        T_map_opt = c.base_T() @ T_base_cam
        rgb, z = self.render(T_map_opt, self._intr.width, self._intr.height, self._proj)
        n, f = self.near, self.far
        depth = (f * n / (f - (f - n) * z)).astype(np.float32)
        depth[z >= 1.0 - 1e-7] = np.nan
        if self._noise.depth > 0:
            depth = depth + (self._noise.depth * depth * depth * c.rng.standard_normal(depth.shape)).astype(np.float32)
        if self._noise.rgb > 0:
            rgb = np.clip(rgb + c.rng.normal(0.0, self._noise.rgb, rgb.shape), 0, 255).astype(np.uint8)
        self.frames += 1
        est = self._base.state().pose.matrix() if self._base is not None else c.base_T()
        return CameraFrame(rgb=rgb, depth=depth, intrinsics=self._intr, stamp=now, T_base_camera=T_base_cam, T_map_base=est)


class SimLidar(Lidar):
    """360 degree planar scan by ray casting (``rayTestBatch``, ``numThreads=0``) in the
    lidar frame: ``beams`` rays from angle -pi CCW, ``range_min`` .. ``range_max`` [m]; no
    return is ``inf``. Range noise is Gaussian with std ``sqrt(noise^2 + (noise_fraction *
    r)^2)`` [m] at range ``r`` (the RPLIDAR A2's error grows with the range).

    ``intensities`` (``quality``):

    * ``binary``: :attr:`REFLECTOR_INTENSITY` where the beam hits one of the world's laser
      reflectors, :attr:`SURFACE_INTENSITY` on any other surface, 0 for no return;
    * ``rplidar_a2``: the device's 6-bit quality over 63, as the driver reports it: a
      reflector returns 56..63, any other surface at most 50 (``47 * (0.6 + 0.4 cos(i)) -
      1.5 r`` plus noise, ``i`` the incidence angle), so the two never overlap.

    A ``reflector_dropout`` fault (:mod:`mmexec.sim.faults`) covers reflectors: they
    return as ordinary surfaces while it lasts.

    ``raycast``: ``pybullet`` casts every beam with ``rayTestBatch``; ``closed_form``
    intersects the beams with the world's fixed boxes and cylinders and its people exactly
    and leaves to pybullet only the beams that may reach anything else first
    (:mod:`mmexec.sim.raycast`: about 5x cheaper a scan in ``lab``; ranges within pybullet's
    own tolerance of about 1 mm of its)."""

    REFLECTOR_INTENSITY = 1.0
    SURFACE_INTENSITY = 0.2

    def __init__(self, core: SimCore, beams: int, range_min: float, range_max: float, noise: float,
                 reflectors: frozenset[str] = frozenset(), *, noise_fraction: float = 0.0,
                 quality: str = "binary", raycast: str = "pybullet") -> None:
        if quality not in ("binary", "rplidar_a2"):
            raise ValueError(f"lidar quality model {quality!r}: expected 'binary' or 'rplidar_a2'")
        if raycast not in ("pybullet", "closed_form"):
            raise ValueError(f"lidar raycast {raycast!r}: expected 'pybullet' or 'closed_form'")
        self._c = core
        names = core.scene.static_names
        #: reflector name -> its link index in the static body
        self._reflector_link = {n: i for i, n in enumerate(names) if n in reflectors}
        self._reflector_links = np.array(sorted(self._reflector_link.values()), dtype=int)
        self.beams, self.range_min, self.range_max, self.noise = beams, range_min, range_max, noise
        self.noise_fraction, self.quality = noise_fraction, quality
        self._inc = 2 * math.pi / beams
        ang = -math.pi + self._inc * np.arange(beams)
        self._dirs = np.stack([np.cos(ang), np.sin(ang), np.zeros(beams)], axis=1)
        self.scans = 0
        self._last: tuple[tuple[int, int, bytes], tuple[np.ndarray, ...]] | None = None
        self._rays: SceneRays | None = None
        if raycast == "closed_form":
            people = core.people.bodies if core.people is not None else []
            self._rays = SceneRays(core.cid, [core.scene.static, core.scene.floor], people)

    def _cast(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The rays of one scan where the world is now: hit fraction (``inf``: no return),
        hit body and link per beam, the beams' directions and hit normals in ``map``, and
        ``T_base_lidar``. The same state gives the same rays, so a second scan in the same
        substep with nothing teleported (the localiser's scan after a spin and the local
        planner's in the next tick) reuses them; its noise is drawn afresh."""
        c = self._c
        T = c.link_T(c.info.lidar_link)
        key = (c.clock.steps, c.teleports, T.tobytes())
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        d = self._dirs @ T[:3, :3].T
        o = T[:3, 3]
        starts = o + d * self.range_min
        ends = o + d * self.range_max
        if self._rays is not None:
            rays = self._rays.cast(starts, ends, d, self.range_max - self.range_min, origin=o)
            frac, body, link, normals = rays.fraction, rays.body, rays.link, rays.normal
        else:
            hits = p.rayTestBatch(starts.tolist(), ends.tolist(), numThreads=0, physicsClientId=c.cid)
            n = len(hits)
            body = np.fromiter((h[0] for h in hits), dtype=np.int64, count=n)
            link = np.fromiter((h[1] for h in hits), dtype=np.int64, count=n)
            frac = np.where(body >= 0, np.fromiter((h[2] for h in hits), dtype=np.float64, count=n), np.inf)
            normals = (np.array([h[4] for h in hits], dtype=np.float64).reshape(-1, 3) if self.quality != "binary"
                       else np.zeros((0, 3)))
        out = (frac, body, link, d, normals, np.linalg.inv(c.base_T()) @ T)
        self._last = (key, out)
        return out

    def scan(self) -> LaserScan | None:
        c = self._c
        now = c.clock.now()
        if c.faults.lidar_dropped(now):
            return None
        frac, body, link, d, normals, T_base_lidar = self._cast()
        links = self._reflector_links
        covered = c.faults.reflectors_covered(now)  # reflector_dropout: None, or the names (empty: all)
        if covered is not None:
            lit = [i for n, i in self._reflector_link.items() if covered and n not in covered]
            links = np.array(lit, dtype=int)
        refl = (body == c.scene.static) & np.isin(link, links)
        ranges = self.range_min + frac * (self.range_max - self.range_min)
        if self.quality == "binary":
            intensity = np.where(np.isfinite(frac), self.SURFACE_INTENSITY, 0.0)
            intensity[refl] = self.REFLECTOR_INTENSITY
        else:
            intensity = self._a2_quality(normals, d, ranges, refl)
        if self.noise_fraction > 0:
            sigma = np.hypot(self.noise, self.noise_fraction * np.where(np.isfinite(ranges), ranges, 0.0))
            ranges = ranges + sigma * c.rng.standard_normal(ranges.shape)
        elif self.noise > 0:
            ranges = ranges + c.rng.normal(0.0, self.noise, ranges.shape)
        self.scans += 1
        return LaserScan(angle_min=-math.pi, angle_increment=self._inc, ranges=ranges.astype(np.float64),
                         range_min=self.range_min, range_max=self.range_max, stamp=now,
                         T_base_lidar=T_base_lidar.copy(), intensities=intensity)

    def _a2_quality(self, normals: np.ndarray, dirs: np.ndarray, ranges: np.ndarray, refl: np.ndarray) -> np.ndarray:
        """RPLIDAR A2-like intensities (quality / 63) of one scan (class doc); ``normals``
        and ``dirs`` per beam in ``map``."""
        rng = self._c.rng
        hit = np.isfinite(ranges)
        cos_i = np.clip(np.abs(np.einsum("ij,ij->i", normals, dirs)), 0.0, 1.0)
        surface = 47.0 * (0.6 + 0.4 * cos_i) - 1.5 * np.where(hit, ranges, 0.0) + rng.normal(0.0, 2.0, len(ranges))
        reflector = 62.0 + rng.normal(0.0, 1.5, len(ranges))
        q = np.where(refl, np.clip(np.round(reflector), 56, 63), np.clip(np.round(surface), 1, 50))
        return np.where(hit, q / 63.0, 0.0)
