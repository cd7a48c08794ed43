"""The pybullet backend: ``build(section, profile=..., seed=..., options=...) -> Robot``.

The executive's config factory calls :func:`build` with the config's ``sim:`` section
(a :class:`~mmexec.config.yamlload.YDict`, or None for all defaults). Keys (all
optional, unknown keys are errors; see docs/sim.md):

``robot`` (the name of a registered robot description, e.g. locobot_wx250s,
ur5e_robotiq, ur3e_robotiq: see :mod:`mmexec.drivers.descriptions`), ``world``
(shipped name or path),
``physics_hz`` (240), ``camera`` (width, height, hfov, near, far, noise, pan, tilt,
mount), ``lidar`` (beams, range_min, range_max, noise, noise_fraction, quality),
``odometry_noise`` (profile, linear, angular, scale, gyro_scale, gyro_bias, slip),
``faults`` (see :mod:`mmexec.sim.faults`), ``randomize`` (false), ``truth_log`` (a
file for the run's ground truth, :mod:`mmexec.sim.truth`; ``{seed}`` is filled in, a
relative path is taken from the config file's folder; none by default).

``options``: ``gui`` (bool) opens the pybullet window; ``record`` (Path or None) writes a
chase-camera video, finalised by :meth:`SimRobot.close`.

:data:`BACKEND` is its :class:`~mmexec.drivers.backendspec.BackendSpec`: a simulated robot
has every capability; ``world`` given as a path is checked when the config loads; the
navigation map is the world's; the campaign's fault profiles set ``faults``
(:data:`FAULTS_OFF`, :data:`FAULT_PATCHES`) and draw the world per trial (``randomize``).
"""

from __future__ import annotations

import enum
import logging
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import pybullet as p

from mmexec.config.yamlload import Mark, Problems, YDict, bind, did_you_mean
from mmexec.drivers import descriptions
from mmexec.drivers.backendspec import CAPABILITIES, BackendSpec, NavMap, SectionFile
from mmexec.drivers.descriptions.head import HeadModel
from mmexec.drivers.interfaces import (
    CameraIntrinsics,
    CapabilityError,
    OccupancyGrid,
    Pose2D,
    ReflectorPost,
    Robot,
)
from mmexec.sim.capabilities import (
    ODOMETRY_PROFILES,
    CameraNoise,
    OdometryNoise,
    SimArm,
    SimBase,
    SimCamera,
    SimClock,
    SimCore,
    SimGripper,
    SimHead,
    SimLidar,
)
from mmexec.sim.clearance import ClearanceMap
from mmexec.sim.faults import FaultConfig, FaultInjector, world_extras
from mmexec.sim.people import SimPeople
from mmexec.sim.plant import RobotBasket
from mmexec.sim.recording import Recorder
from mmexec.sim.scene import (
    GROUP_ARM,
    GROUP_BODY,
    GROUP_ITEM,
    GROUP_QUERY,
    GROUP_STATIC,
    spawn_world,
)
from mmexec.sim.truth import TruthLog, open_truth_log, truth_log_path
from mmexec.sim.world import WORLDS_DIR, World, load_world

__all__ = ["BACKEND", "FAULTS_OFF", "FAULT_PATCHES", "CameraSection", "LidarSection", "OdometrySection", "SimError",
           "SimRobot", "SimSection", "SimTruth", "build", "parse_section"]

log = logging.getLogger(__name__)


class SimError(CapabilityError):
    """The simulation cannot start as asked (no display for the GUI, bad record path)."""


@dataclass(frozen=True)
class CameraSection:
    """Camera: image ``width``/``height`` [px] and horizontal FOV ``hfov`` [rad] (None =
    the model's default: 640 x 480, 0.994837 rad on the LoCoBot), clip ``near``/``far``
    [m], ``noise``, LoCoBot head ``pan``/``tilt`` [rad], and for a wrist camera a
    ``mount`` correction [x, y, z, roll, pitch, yaw] (m, rad) of the optical frame."""

    width: int | None = None
    height: int | None = None
    hfov: float | None = None
    near: float = 0.01
    far: float = 10.0
    noise: CameraNoise = field(default_factory=CameraNoise)
    pan: float = 0.0
    tilt: float = 0.0
    mount: tuple[float, float, float, float, float, float] | None = None

    def validate(self) -> list[str]:
        out = []
        if (self.width is not None and not 16 <= self.width <= 4096) or (self.height is not None and not 16 <= self.height <= 4096):
            out.append("camera width and height must be 16..4096 px")
        if self.hfov is not None and not 0.1 < self.hfov < 3.0:
            out.append(f"camera hfov {self.hfov} rad outside (0.1, 3.0)")
        if not 0 < self.near < self.far:
            out.append(f"camera needs 0 < near < far, got near={self.near}, far={self.far}")
        return out


@dataclass(frozen=True)
class LidarSection:
    """Lidar: ``beams`` per 360 degree scan (RPLIDAR A2 at 10 Hz: 800 at 8 k samples/s,
    400 at 4 k; default 400 as the official Gazebo stand-in), ``range_min``/``range_max``
    [m], range noise std ``noise`` [m] plus ``noise_fraction`` of the range (in
    quadrature; the A2's error is about 1 % of the range), intensity ``quality`` model
    (``binary`` 1.0 / 0.2, or ``rplidar_a2``: the device's quality / 63, see
    :class:`~mmexec.sim.capabilities.SimLidar`), and how the beams are cast (``raycast``:
    ``pybullet``, every beam by pybullet's ``rayTestBatch``, or ``closed_form``, the fixed
    boxes and cylinders and the people intersected exactly, about 5x cheaper, ranges
    within pybullet's own ~1 mm tolerance: :mod:`mmexec.sim.raycast`)."""

    beams: int = 400
    range_min: float = 0.15
    range_max: float = 12.0
    noise: float = 0.01
    noise_fraction: float = 0.0
    quality: Literal["binary", "rplidar_a2"] = "binary"
    raycast: Literal["pybullet", "closed_form"] = "pybullet"

    def validate(self) -> list[str]:
        out = []
        if not 8 <= self.beams <= 16000:
            out.append(f"lidar beams {self.beams} outside 8..16000")
        if not 0 <= self.range_min < self.range_max:
            out.append(f"lidar needs 0 <= range_min < range_max, got {self.range_min}, {self.range_max}")
        if self.noise < 0 or self.noise_fraction < 0:
            out.append("lidar noise and noise_fraction must be >= 0")
        return out


@dataclass(frozen=True)
class OdometrySection:
    """Odometry noise: a named ``profile`` (:data:`~mmexec.sim.capabilities.ODOMETRY_PROFILES`:
    ``default``, or ``realistic`` for the localisation campaigns) whose values any key
    given here replaces (see :class:`~mmexec.sim.capabilities.OdometryNoise` for each)."""

    profile: Literal["default", "realistic"] = "default"
    linear: float | None = None
    angular: float | None = None
    scale: float | None = None
    gyro_scale: float | None = None
    gyro_bias: float | None = None
    slip: float | None = None

    def model(self) -> OdometryNoise:
        """The profile with this section's values in place of its own."""
        given = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "profile"}
        return replace(ODOMETRY_PROFILES[self.profile], **{k: v for k, v in given.items() if v is not None})

    def validate(self) -> list[str]:
        return self.model().validate()


#: ``sim.robot``: the name of a registered robot description (a str), so a robot added to
#: :data:`mmexec.drivers.descriptions.DESCRIPTIONS` can be simulated without an edit here.
RobotModel = enum.StrEnum("RobotModel", {name: name for name in descriptions.names()})  # type: ignore[misc]


@dataclass(frozen=True)
class SimSection:
    """The ``sim:`` config section."""

    robot: RobotModel = RobotModel["locobot_wx250s"]
    world: str = "lab"
    physics_hz: int = 240
    camera: CameraSection = field(default_factory=CameraSection)
    lidar: LidarSection = field(default_factory=LidarSection)
    odometry_noise: OdometrySection = field(default_factory=OdometrySection)
    faults: FaultConfig = field(default_factory=FaultConfig)
    randomize: bool = False
    truth_log: str | None = None
    basket: RobotBasket | None = None  #: a basket on the robot (sim/plant.py; the fruit mission drops into it)

    def validate(self) -> list[str]:
        return [] if 30 <= self.physics_hz <= 2000 else [f"physics_hz {self.physics_hz} outside 30..2000"]


def parse_section(section: YDict | Mapping[str, Any] | None) -> SimSection:
    """Bind a ``sim:`` section into :class:`SimSection`; raises :class:`InputError`."""
    problems = Problems()
    mark = getattr(section, "mark", Mark("<sim>", 1, 1))
    out = bind(SimSection, section, mark, "sim", problems)
    problems.raise_if_any()
    assert isinstance(out, SimSection)
    return out


def _check_fault_items(cfg: SimSection, world: World, section: Any) -> None:
    """The items and reflectors the faults name exist in ``world``; a kidnap pose lies in
    the room."""
    faults = section.get("faults") if isinstance(section, Mapping) else None
    default = getattr(section, "mark", Mark("<sim>", 1, 1))

    def mark(key: str) -> Mark:
        return faults.value_mark(key.split(".")[0]) if isinstance(faults, YDict) else default

    problems = Problems()
    kinds = (("item", "items", set(world.item_names()), cfg.faults.item_names()),
             ("reflector", "reflectors", {r.name for r in world.spec.reflectors},
              [("reflector_dropout.reflectors", n) for n in cfg.faults.reflector_dropout.reflectors]))
    for what, plural, names, refs in kinds:
        for key, name in refs:
            if name not in names:
                problems.add(mark(key), f"sim.faults.{key}: no {what} {name!r} in world {world.name!r}"
                             + (did_you_mean(name, names) or f" ({plural}: {', '.join(sorted(names)) or 'none'})"))
    kid = cfg.faults.kidnap
    if kid is not None and kid.pose is not None:
        radius = descriptions.get(cfg.robot).info.footprint_radius
        if not _map_clearance(world.occupancy(0.05))(kid.pose[0], kid.pose[1], radius):
            problems.add(mark("kidnap"), f"sim.faults.kidnap.pose: the base ({radius} m radius) at ({kid.pose[0]}, "
                                         f"{kid.pose[1]}) would overlap the static geometry of world {world.name!r}")
    problems.raise_if_any()


def world_reflectors(world: World) -> tuple[ReflectorPost, ...]:
    """The world's laser-reflector posts, as the map the robot is given lists them."""
    return tuple(ReflectorPost(r.name, (float(r.position[0]), float(r.position[1])), r.radius)
                 for r in world.spec.reflectors)


def _map_clearance(grid: OccupancyGrid) -> Callable[[float, float, float], bool]:
    """``clear(x, y, r)``: whether a disk of radius ``r`` [m] at map point ``(x, y)`` lies in
    ``grid`` and away from its occupied cells (to within a cell)."""
    free = np.where(grid.data >= 50, 0, 255).astype(np.uint8)
    dist = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * grid.resolution

    def clear(x: float, y: float, r: float) -> bool:
        col = math.floor((x - grid.origin.x) / grid.resolution)
        row = math.floor((y - grid.origin.y) / grid.resolution)
        return 0 <= row < grid.height and 0 <= col < grid.width and float(dist[row, col]) > r

    return clear


@dataclass
class SimTruth:
    """Ground truth, SIM-ONLY: for tests and campaign scoring, never for skills."""

    _robot: SimRobot

    def base_pose(self) -> Pose2D:
        """True base pose in ``map``."""
        return self._robot.core.true_pose

    def item_pose(self, name: str) -> np.ndarray:
        """True ``T_map_item`` (box centre; marker on the local +x face)."""
        r = self._robot
        pos, orn = p.getBasePositionAndOrientation(r.scene_handles.items[name], physicsClientId=r.cid)
        T = np.eye(4)
        T[:3, :3] = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
        T[:3, 3] = pos
        return T

    def item_poses(self) -> dict[str, np.ndarray]:
        return {n: self.item_pose(n) for n in self._robot.world.item_names()}

    def held_item(self) -> str | None:
        g = self._robot.gripper
        return g.held if isinstance(g, SimGripper) else None

    def in_depot(self, name: str) -> str | None:
        """Name of the depot whose basket holds item ``name`` (centre inside the walls,
        below the rim, not held), or None."""
        if self.held_item() == name:
            return None
        T = self.item_pose(name)
        for d in self._robot.world.spec.depots:
            c, s = math.cos(d.pose[2]), math.sin(d.pose[2])
            dx, dy = T[0, 3] - d.pose[0], T[1, 3] - d.pose[1]
            lx, ly = c * dx + s * dy, -s * dx + c * dy
            if abs(lx) < d.size[0] / 2 and abs(ly) < d.size[1] / 2 and T[2, 3] < d.size[2] + 0.05:
                return d.name
        return None

    def items_in_depot(self) -> dict[str, str]:
        return {n: d for n in self._robot.world.item_names() if (d := self.in_depot(n)) is not None}

    def faults_fired(self) -> list[tuple[float, str]]:
        return list(self._robot.injector.fired)


class SimRobot(Robot):
    """A simulated robot in a world. Build with :func:`build`."""

    def __init__(self, *, cid: int, core: SimCore, world: World, cfg: SimSection, profile: dict[str, Any],
                 scene_handles: Any, injector: FaultInjector, recorder: Recorder | None) -> None:
        self.cid, self.core, self.world, self.config = cid, core, world, cfg
        self.name = f"sim:{cfg.robot}@{world.name}"
        self.description = descriptions.get(cfg.robot)
        self.scene_handles = scene_handles
        self.injector = injector
        self.recorder = recorder
        self.clock = core.clock
        self.profile = profile
        self.occupancy = replace(world.occupancy(0.05), reflectors=world_reflectors(world))
        self.scene = world.scene_boxes()
        info = core.info
        self.base = SimBase(core, cfg.odometry_noise.model(), info.bump_links)
        self.arm = SimArm(core)
        self.gripper = SimGripper(core)
        w, h = cfg.camera.width or info.camera_size[0], cfg.camera.height or info.camera_size[1]
        intr = CameraIntrinsics.from_fov(w, h, cfg.camera.hfov or info.camera_hfov)
        mount = None
        if cfg.camera.mount is not None:
            x, y, z, r, pp, yw = cfg.camera.mount
            mount = np.eye(4)
            mount[:3, :3] = np.array(p.getMatrixFromQuaternion(p.getQuaternionFromEuler((r, pp, yw)))).reshape(3, 3)
            mount[:3, 3] = (x, y, z)
        self.camera = SimCamera(core, intr, cfg.camera.near, cfg.camera.far, cfg.camera.noise, self.base, mount)
        self.head: SimHead | None = None
        if info.pan_tilt_joints:
            # the head starts (and its home is) at sim.camera.pan/tilt
            self.head = SimHead(core, (cfg.camera.pan, cfg.camera.tilt), HeadModel.of(self.description))
            self.head.teleport(cfg.camera.pan, cfg.camera.tilt)
        lid = cfg.lidar
        self.lidar = SimLidar(core, lid.beams, lid.range_min, lid.range_max, lid.noise,
                              reflectors=frozenset(r.name for r in world.spec.reflectors),
                              noise_fraction=lid.noise_fraction, quality=lid.quality, raycast=lid.raycast)
        self.truth = SimTruth(self)  #: SIM-ONLY ground truth (tests, campaign scoring)
        core.clearance = ClearanceMap.from_world(world, *self.base.bump_heights)
        self._item_radius = {it.name: 0.5 * math.sqrt(sum(x * x for x in it.size)) for it in world.spec.items}
        if scene_handles.plants is not None:  # the fruit are items too (the gripper holds them)
            self._item_radius.update({n: f.radius for n, f in scene_handles.plants.fruit.items()})
        self._item_radius.update({o.name: 0.5 * math.sqrt(sum(x * x for x in o.model.size)) for o in world.spec.objects})
        self.physics_steps = 0  #: substeps that ran stepSimulation (the others were at rest)
        self.truth_log: TruthLog | None = None  #: SIM-ONLY ground-truth sidecar (``sim.truth_log``)
        self._kidnap_pending = cfg.faults.kidnap is not None
        self._closed = False

    def _at_rest(self, period: float) -> bool:
        """Whether ``period`` [s] of physics can be skipped without changing anything a
        step would change: arm and gripper at rest with nothing held, every item still
        (Bullet zeroes the velocities of sleeping bodies), and the robot either not moving
        or, while it drives, farther from every item than its own radius plus the distance
        it can cover in ``period`` (5 cm margin). The kinematic base and the clock advance
        either way. The decision depends only on the simulation state, so a seed still
        reproduces a run."""
        if not (self.arm.at_rest() and self.gripper.at_rest()) or (self.head is not None and not self.head.at_rest()):
            return False
        panels = self.scene_handles.panels
        if panels is not None and not panels.at_rest():  # a button still springing back
            return False
        cid = self.cid
        items = self.scene_handles.items
        for body in items.values():
            v, w = p.getBaseVelocity(body, physicsClientId=cid)
            if v[0] * v[0] + v[1] * v[1] + v[2] * v[2] > 1e-6 or w[0] * w[0] + w[1] * w[1] + w[2] * w[2] > 1e-4:
                return False
        if self.base.still():
            return True
        core = self.core
        core.sync()
        bx, by = core.true_pose.x, core.true_pose.y
        reach = 0.0
        for li in range(-1, p.getNumJoints(core.body, physicsClientId=cid)):
            lo, hi = p.getAABB(core.body, li, physicsClientId=cid)
            reach = max(reach, math.hypot(max(abs(lo[0] - bx), abs(hi[0] - bx)), max(abs(lo[1] - by), abs(hi[1] - by))))
        reach += self.base.max_linear * period + 0.05
        for name, body in items.items():
            pos = p.getBasePositionAndOrientation(body, physicsClientId=cid)[0]
            if math.hypot(pos[0] - bx, pos[1] - by) < reach + self._item_radius[name]:
                return False
        return True

    def spin(self, period: float) -> None:
        """Step physics by exactly ``period`` [s] of sim time: period * physics_hz whole substeps."""
        if self._closed:
            raise SimError("spin() after close()")
        hz = self.clock.hz
        n = round(period * hz)
        if n < 1 or abs(n - period * hz) > 1e-6 * max(1.0, period * hz):
            raise ValueError(f"period {period} s is not a whole number of {hz} Hz physics substeps")
        dt = 1.0 / hz
        rest = self._at_rest(period)
        core = self.core
        for _ in range(n):
            if self._kidnap_pending:
                self._kidnap()
            if core.people is not None:
                core.people.step(dt, (core.true_pose.x, core.true_pose.y), core.info.footprint_radius,
                                 core.clearance.clear if core.clearance is not None else None)
            self.base.update(dt)
            if not rest:
                self.arm.update(dt)
                self.gripper.update(dt)
                if self.head is not None:
                    self.head.update(dt)
                core.sync()
                p.stepSimulation(physicsClientId=self.cid)
                self.physics_steps += 1
                if self.scene_handles.panels is not None:
                    self.scene_handles.panels.step(self.clock.now() + dt)
            self.clock.steps += 1
            if self.recorder is not None:
                core.sync()
                tp = core.true_pose
                self.recorder.sample(self.clock.now(), (tp.x, tp.y), tp.theta)
        if self.scene_handles.plants is not None:  # magnets pulled off let go; fruit truth
            self.scene_handles.plants.tick(self.clock.now(), core.held_body, self.truth_log)
        if self.truth_log is not None:
            self.truth_log.sample()

    def _kidnap(self) -> None:
        """The ``kidnap`` fault: once due, put the base at the injector's pose (the
        odometry keeps integrating from where it was)."""
        core = self.core
        here = core.true_pose
        sx, sy = self.world.spec.room.size
        clearance = core.clearance
        margin = self.base.bump_radius + 0.05
        in_map = _map_clearance(self.occupancy)  # also away from what only the map shows (a table top)

        def clear(x: float, y: float) -> bool:
            return in_map(x, y, margin) and clearance is not None and clearance.clear(x, y, margin)

        pose = self.injector.kidnap_pose(self.clock.now(), (here.x, here.y), clear, (0.0, 0.0, sx, sy))
        if pose is not None:
            self._kidnap_pending = False
            core.place_base(Pose2D(*pose))

    def close(self) -> None:
        if self._closed:
            return
        self.safe_stop()
        self._closed = True
        try:
            if self.truth_log is not None:
                self.truth_log.close()
            if self.recorder is not None:
                self.recorder.close()
        finally:
            p.disconnect(physicsClientId=self.cid)


def build(section: YDict | None, *, profile: Mapping[str, Any], seed: int | None,
          options: Mapping[str, Any]) -> SimRobot:
    """Build a simulated robot from a ``sim:`` config section (see module doc).

    Raises :class:`InputError` for a bad section or world file (``FILE:LINE:COL``),
    :class:`SimError` when the GUI or recording cannot start.
    """
    cfg = parse_section(section)
    wmark = section.value_mark("world") if isinstance(section, YDict) and "world" in section else None
    world = load_world(cfg.world, seed=seed, randomize=cfg.randomize, mark=wmark)
    _check_fault_items(cfg, world, section)
    extra_obstacles, extra_people = world_extras(world, cfg.faults, seed,
                                                 descriptions.get(cfg.robot).info.footprint_radius)
    if extra_obstacles or extra_people:
        world = load_world(cfg.world, seed=seed, randomize=cfg.randomize, mark=wmark,
                           extra_obstacles=extra_obstacles, extra_people=extra_people)
    truth_path = None
    if cfg.truth_log is not None:
        tmark = section.value_mark("truth_log") if isinstance(section, YDict) else Mark("<sim>", 1, 1)
        truth_path = truth_log_path(cfg.truth_log, tmark, seed)
    record = options.get("record")
    if record is not None:
        rp = Path(record)
        if rp.suffix.lower() not in (".mp4", ".gif"):
            raise SimError(f"--record {record}: the file must end in .mp4 or .gif")
        try:
            rp.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise SimError(f"--record {record}: cannot create the folder {rp.parent} ({e.strerror or e})") from e
        if not os.access(rp.parent, os.W_OK):
            raise SimError(f"--record {record}: the folder {rp.parent} is not writable")
    if options.get("gui"):
        if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
            raise SimError("--gui: no display (DISPLAY is not set); run headless or under a desktop session")
        cid = p.connect(p.GUI)
    else:
        cid = p.connect(p.DIRECT)
    if cid < 0:
        raise SimError("pybullet could not start a physics client")
    try:
        p.setGravity(0, 0, -9.81, physicsClientId=cid)
        p.setTimeStep(1.0 / cfg.physics_hz, physicsClientId=cid)
        p.setPhysicsEngineParameter(numSolverIterations=30, deterministicOverlappingPairs=1, physicsClientId=cid)
        handles = spawn_world(world, cid, marker_bias=cfg.faults.marker_bias, robot_basket=cfg.basket)
        description = descriptions.get(cfg.robot)
        info = description.info
        body = p.loadURDF(str(description.urdf_path), [world.start.x, world.start.y, 0.0],
                          p.getQuaternionFromEuler((0, 0, world.start.theta)), useFixedBase=True,
                          flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=cid)
        links, joints = {}, {}
        moving = set(info.arm_joints) | set(info.gripper_joints)
        on_arm: dict[int, bool] = {-1: False}
        for i in range(p.getNumJoints(body, physicsClientId=cid)):
            ji = p.getJointInfo(body, i, physicsClientId=cid)
            links[ji[12].decode()] = i
            joints[ji[1].decode()] = i
            if ji[2] != p.JOINT_FIXED:
                p.setJointMotorControl2(body, i, p.VELOCITY_CONTROL, force=0.0 if ji[2] == p.JOINT_REVOLUTE and "wheel" in ji[1].decode() else 1.0, physicsClientId=cid)
            # arm and gripper links collide with static geometry and items; links that
            # move only with the kinematic base touch items only (bumpers are queried)
            on_arm[i] = on_arm[ji[16]] or ji[1].decode() in moving
            group, mask = (GROUP_ARM, GROUP_QUERY | GROUP_STATIC | GROUP_ITEM) if on_arm[i] else (GROUP_BODY, GROUP_QUERY | GROUP_ITEM)
            p.setCollisionFilterGroupMask(body, i, group, mask, physicsClientId=cid)
        p.setCollisionFilterGroupMask(body, -1, GROUP_BODY, GROUP_QUERY | GROUP_ITEM, physicsClientId=cid)
        for name in info.finger_links:
            p.changeDynamics(body, links[name], lateralFriction=1.0, physicsClientId=cid)
        rng = np.random.default_rng(seed)
        injector = FaultInjector(cfg.faults, np.random.default_rng(rng.integers(2**63)))
        core = SimCore(cid=cid, body=body, info=info, clock=SimClock(cfg.physics_hz),
                       rng=np.random.default_rng(rng.integers(2**63)), faults=injector, scene=handles,
                       links=links, joints=joints, true_pose=world.start)
        core.place_base(world.start)
        if world.people:
            core.people = SimPeople(world.people, cid)
        recorder = Recorder(Path(record), cid) if record is not None else None
        robot = SimRobot(cid=cid, core=core, world=world, cfg=cfg, profile=dict(profile), scene_handles=handles,
                         injector=injector, recorder=recorder)
        robot.arm.set_positions(info.sleep_pose)
        robot.gripper.set_width(robot.gripper.max_width)
        if truth_path is not None:
            try:
                robot.truth_log = open_truth_log(truth_path, core, world, seed, info.footprint_radius,
                                                 robot.base.bump_heights,
                                                 frozenset(i for i, arm in on_arm.items() if arm and i >= 0))
            except OSError as e:
                raise SimError(f"sim.truth_log {truth_path}: cannot write: {e.strerror or e}") from e
            if handles.plants is not None:
                robot.truth_log.record("fruit_start", **handles.plants.start_record())
        return robot
    except BaseException:
        p.disconnect(physicsClientId=cid)
        raise


# --------------------------------------------------------------------------- the backend spec


def capabilities(cfg: SimSection) -> frozenset[str]:
    """A simulated robot has every capability, whatever its section says."""
    return frozenset(CAPABILITIES)


def is_world_path(value: str) -> bool:
    """``sim.world`` is read as a path (from the current folder) when it has a '/' or a
    .yaml/.yml ending, as the name of a shipped world otherwise."""
    return "/" in value or value.endswith((".yaml", ".yml"))


def navigation(section: YDict | None) -> NavMap:
    """The map of the section's world (nominal poses) and the simulated robot's footprint
    radius, found without starting physics; InputError for a bad section or world file."""
    from mmexec.sim.mapgen import world_map

    cfg = parse_section(section)
    mark = section.value_mark("world") if isinstance(section, YDict) and "world" in section else None
    world = load_world(cfg.world, randomize=False, mark=mark)
    return NavMap(replace(world_map(world), reflectors=world_reflectors(world)),
                  descriptions.get(cfg.robot).info.footprint_radius, f"the map of world {world.name!r}")


def item_markers(section: Mapping[str, Any] | None) -> tuple[int, ...]:
    """The marker ids of the items of the section's world (nominal world, ``lab`` by
    default)."""
    world = load_world(str((section or {}).get("world", "lab")))
    return tuple(it.marker for it in world.spec.items)


def object_names(section: Mapping[str, Any] | None) -> tuple[str, ...]:
    """The names of the untagged objects of the section's world (sim/objects.py)."""
    return load_world(str((section or {}).get("world", "lab"))).object_names()


#: Merge patch of the ``sim:`` section that switches every injected fault off (sensor and
#: odometry noise stay as configured).
FAULTS_OFF: dict[str, Any] = {"faults": None}

#: Built-in fault profile (``mmexec campaign --faults``) -> its ``sim.faults``, on top of
#: :data:`FAULTS_OFF` (:mod:`mmexec.sim.faults`; goal numbers count every arm goal of the
#: trial, so in ``fetch_item`` goal 1 is the initial tuck).
FAULT_PATCHES: dict[str, dict[str, Any]] = {
    "arm_fail_first": {"faults": {"arm_fail_attempts": [1]}},
    "arm_fail_second": {"faults": {"arm_fail_attempts": [2]}},
    "arm_fail_twice": {"faults": {"arm_fail_attempts": [1, 2]}},
    "arm_fail_always": {"faults": {"arm_fail": "always"}},
    "sensor_dropout": {"faults": {"camera_dropout": {"p": 0.2}, "lidar_dropout": {"p": 0.2}}},
    # the world faults: their defaults (mmexec.sim.faults), and each trial's ground truth
    # (mmexec.sim.truth) written to DIR/truth/SEED.jsonl beside DIR/config.yaml
    "crowd": {"faults": {"crowd": {}}, "truth_log": "truth/{seed}.jsonl"},
    "clutter": {"faults": {"clutter": {}}, "truth_log": "truth/{seed}.jsonl"},
    # not a fault but the drift of a real base's odometry, for the localisation campaigns
    "realistic_odometry": {"odometry_noise": {"profile": "realistic"}},
}

#: The ``sim`` backend, as the executive's registry sees it.
BACKEND: BackendSpec[SimSection] = BackendSpec(
    name="sim",
    parse_section=parse_section,
    capabilities=capabilities,
    build=build,
    options=frozenset({"gui", "record"}),
    files=(SectionFile("world", "a world", (WORLDS_DIR,), is_world_path),),
    navigation=navigation,
    faults_off=FAULTS_OFF,
    fault_patches=FAULT_PATCHES,
    randomize_key="randomize",
    truth_key="truth_log",
    item_markers=item_markers,
    object_names=object_names,
)
