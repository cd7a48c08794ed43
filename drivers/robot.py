"""The ``robot`` backend: a run config's ``robot:`` section into a :class:`RealRobot`.

Section schema (every device optional; see docs/drivers/bringup.md)::

    robot:
      name: locobot
      description: locobot_wx250s    # the robot model (mmexec.drivers.descriptions): skills plan with it
      base:    {kind: kobuki, port: /dev/kobuki, start: [x, y, theta], ...KobukiConfig keys}
      arm:     {kind: wx250s, port: /dev/ttyDXL, baudrate: 1000000, locobot: true, ...WX250sConfig keys}
               # or {kind: ur, host: 192.168.1.10, ...}
      gripper: {kind: wx250s_gripper}                         # the arm's own gripper servo
               # or {kind: robotiq_rtu, port: /dev/ttyUSB0, slave: 9, max_force: 100, activate: true}
               # or {kind: robotiq_urcap, host: 192.168.1.10, ...}
      head:    {kind: wx250s_head, home: [pan, tilt]}         # the LoCoBot's pan/tilt servos 10, 11 on the
                                                              # arm's bus (arm locobot: true); home [rad]
      camera:  {kind: uvc | realsense, device: 0, width: 640, height: 480, fps: 30,
                intrinsics: {fx, fy, cx, cy, dist} | hfov: RAD, frame_timeout: 0.5,
                pose_in_base: {xyz: [..], rpy: [..]}, mount_link: base_link | tool0 | head}
               # ...CameraConfig keys (docs/drivers/camera.md); mount_link tool0 = wrist
               # camera on a UR arm, pose_in_base then being T_tool0_camera; head = on the
               # pan/tilt head, pose_in_base then being the pose at pan = tilt = 0
      lidar:   {kind: rplidar, port: /dev/rplidar, pose_in_base: {xyz: [..], rpy: [..]},
                ...RplidarConfig keys}                        # pose of the CCW scan frame
      map:     {yaml: maps/lab.yaml}                           # map_server YAML + PGM
      scene:   [{name: shelf, size: [x, y, z], xyz: [..], rpy: [..]}]   # static boxes in map

Two phases, as everywhere in mmexec: the whole section is bound and checked first
(every problem reported as ``FILE:LINE:COL: robot.key: message``), then devices are
constructed lazily by ``kind`` through :data:`DEVICE_KINDS` (driver modules are
imported only when a config names them) and connected in order base, arm, gripper, head,
camera, lidar. Before the first device is opened, the driver objects that need an optional
extra are constructed (no I/O), so a missing ``pyrealsense2`` fails at once. A device that
does not answer raises :class:`DeviceUnavailable`, a one-line error naming the config
line, the device and its port, after closing what was opened.
Relative paths (``map.yaml``) are relative to the config file.

:data:`BACKEND` is its :class:`~mmexec.drivers.backendspec.BackendSpec`: the capabilities
are the planned device slots (:func:`check`, nothing opened); the navigation map is
``robot.map``; no run option applies and no fault is injected (a campaign runs the config
as written).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import logging
import math
import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mmexec.config.yamlload import InputError, Mark, Problem, Problems, YDict, bind, did_you_mean
from mmexec.drivers import descriptions
from mmexec.drivers.backendspec import BackendSpec, NavMap
from mmexec.drivers.interfaces import (
    CapabilityError,
    MonotonicClock,
    OccupancyGrid,
    Pose2D,
    Robot,
    SceneBox,
)

__all__ = [
    "BACKEND",
    "DEVICE_KINDS",
    "BringUpInterrupted",
    "DeviceUnavailable",
    "RealRobot",
    "SinceStartClock",
    "build",
    "check",
    "check_navigation",
    "pose_matrix",
]

log = logging.getLogger(__name__)



class BringUpInterrupted(KeyboardInterrupt):
    """A halting signal (SIGINT, SIGTERM or SIGHUP, number ``signum``) ended the device
    bring-up; :func:`build` closed what it had opened. A KeyboardInterrupt, so every wait
    that gives up on Ctrl-C (:meth:`URArm.open <mmexec.drivers.ur.arm.URArm.open>`)
    gives up on any of the three."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"interrupted by {signal.Signals(signum).name} during device bring-up")
        self.signum = signum


class DeviceUnavailable(InputError):
    """A configured device could not be brought up (no such port, no answer, fault).

    An :class:`InputError` located at the device's config section, because the fix is
    usually there or in the wiring: ``FILE:LINE:COL: robot.base: kobuki on PORT: reason``.
    """


# --------------------------------------------------------------------------- robot


class SinceStartClock(MonotonicClock):
    """The real robot's clock: monotonic wall-clock seconds since the clock was made (when
    the robot was built), so clock times (the event log's ``t``, ``run_end``'s duration)
    count from the start of the run as the sim's and the mock's do."""

    def __init__(self) -> None:
        self._origin = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self._origin


class RealRobot(Robot):
    """The real robot: capabilities backed by drivers, a monotonic wall clock counting
    seconds since the robot was built (:class:`SinceStartClock`)."""

    def __init__(self, name: str, profile: Mapping[str, Any], clock: MonotonicClock | None = None) -> None:
        self.name = name
        self.clock = clock or SinceStartClock()
        self.profile = dict(profile)
        self._closers: list[tuple[str, Callable[[], None]]] = []
        self._next_tick: float | None = None
        self.overruns = 0

    def add_closer(self, label: str, closer: Callable[[], None]) -> None:
        """Register a device shutdown, run (in reverse order) by :meth:`close`."""
        self._closers.append((label, closer))

    def spin(self, period: float) -> None:
        """Sleep until the next ``period`` [s] boundary of the wall clock. When the tick
        ran past the boundary, the schedule restarts from now (counted in ``overruns``)."""
        if not period > 0:
            raise ValueError(f"spin period must be > 0 s, got {period}")
        now = self.clock.now()
        if self._next_tick is None:
            self._next_tick = now
        self._next_tick += period
        delay = self._next_tick - now
        if delay < 0:
            self.overruns += 1
            log.debug("tick overran its period by %.1f ms", -delay * 1e3)
            self._next_tick = now
            return
        time.sleep(delay)

    def safe_stop(self) -> None:
        """Base zero velocity, arm and head holding; gripper unchanged. Never raises."""
        for label, cap in (("base", self.base), ("arm", self.arm), ("head", self.head)):
            if cap is None:
                continue
            try:
                cap.stop()
            except Exception:
                log.exception("safe_stop: %s.stop() failed", label)

    def close(self) -> None:
        """Stop everything, then close every device (last opened first). Idempotent."""
        self.safe_stop()
        closers, self._closers = self._closers, []
        for label, closer in reversed(closers):
            try:
                closer()
            except Exception:
                log.exception("close: %s failed", label)


# --------------------------------------------------------------------------- section schema


@dataclass(frozen=True)
class MapSection:
    """``map:``: a map_server map (YAML + PGM), path relative to the config file."""

    yaml: str


@dataclass(frozen=True)
class SceneBoxSection:
    """One static box: full ``size`` [m], centre ``xyz`` [m] and ``rpy`` [rad] in ``map``."""

    name: str
    size: tuple[float, float, float]
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def validate(self) -> list[str]:
        return [] if all(s > 0 for s in self.size) else [f"size: every extent must be > 0 m, got {list(self.size)}"]


def pose_matrix(xyz: tuple[float, float, float], rpy: tuple[float, float, float]) -> np.ndarray:
    """4x4 transform from a translation [m] and roll, pitch, yaw [rad] (R = Rz Ry Rx)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    T = np.eye(4)
    T[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    T[:3, 3] = xyz
    return T


# --------------------------------------------------------------------------- device kinds


@dataclass
class _Ctx:
    """Build state shared by the device factories."""

    robot: RealRobot
    problems: Problems
    devices: dict[str, Any] = field(default_factory=dict)   # slot -> driver device object
    #: checks without I/O that build() runs before opening any device (optional extras)
    prepare: list[Callable[[], None]] = field(default_factory=list)
    #: the planned base's footprint radius [m] (its Base.radius once connected)
    base_radius: float | None = None


#: a planned device: (slot, label for errors, mark, connect function returning the capability)
_Plan = tuple[str, str, Mark, Callable[[], Any]]
_Factory = Callable[[YDict, str, _Ctx], "_Plan | None"]


def _without(section: YDict, *keys: str) -> YDict:
    """A copy of ``section`` without ``keys``, keeping the marks of the rest."""
    out = YDict({k: v for k, v in section.items() if k not in keys})
    out.mark = section.mark
    out.key_marks = {k: m for k, m in section.key_marks.items() if k not in keys}
    out.value_marks = {k: m for k, m in section.value_marks.items() if k not in keys}
    return out


def _split(section: YDict, *types: type) -> list[YDict]:
    """Split ``section``'s keys between dataclasses by field name (first match wins);
    keys no dataclass knows stay in the first part, so binding reports them."""
    names = [{f.name for f in dataclasses.fields(t)} for t in types]
    parts: list[YDict] = []
    taken: set[str] = set()
    for i, fields in enumerate(names):
        keep = [k for k in section if k in fields and k not in taken]
        if i == 0:
            known = set().union(*names)
            keep += [k for k in section if k not in known]
        taken.update(keep)
        parts.append(_without(section, *[k for k in section if k not in keep]))
    return parts


def _import(module: str, what: str, mark: Mark, path: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as e:
        raise InputError.at(
            mark, f"{path}: {what} needs {module}, which is not in this installation ({e.name} not found)"
        ) from None


def _connect_error(path: str, mark: Mark, message: str) -> DeviceUnavailable:
    return DeviceUnavailable([Problem(mark, f"{path}: {message}")])


def _kobuki(section: YDict, path: str, ctx: _Ctx) -> _Plan | None:
    from mmexec.drivers.kobuki.base import KobukiBase
    from mmexec.drivers.kobuki.device import KobukiConfig, KobukiDevice, KobukiError

    @dataclass(frozen=True)
    class _Start:
        """``start``: pose in map at power-up [m, m, rad]; ``footprint_radius`` [m]: the
        circle covering what the base carries (default: the Kobuki body's 0.178 m)."""

        start: tuple[float, float, float] = (0.0, 0.0, 0.0)
        footprint_radius: float | None = None

        def validate(self) -> list[str]:
            r = self.footprint_radius
            if r is not None and not KobukiBase.radius <= r <= 2.0:
                return [f"footprint_radius: expected {KobukiBase.radius}..2.0 m (at least the Kobuki body), got {r}"]
            return []

    cfg_part, start_part = _split(_without(section, "kind"), KobukiConfig, _Start)
    cfg = bind(KobukiConfig, cfg_part, section.mark, path, ctx.problems)
    start = bind(_Start, start_part, section.mark, path, ctx.problems)
    if cfg is None or start is None:
        return None
    ctx.base_radius = start.footprint_radius if start.footprint_radius is not None else KobukiBase.radius

    def connect() -> KobukiBase:
        dev = KobukiDevice(cfg, ctx.robot.clock)
        try:
            dev.connect()
        except KobukiError as e:
            raise _connect_error(path, section.mark, str(e)) from e
        ctx.robot.add_closer(f"kobuki on {cfg.port}", dev.close)
        dev.reset_odometry(Pose2D(*start.start))
        return KobukiBase(dev, footprint_radius=start.footprint_radius)

    return ("base", f"kobuki on {cfg.port}", section.mark, connect)


def _wx250s(section: YDict, path: str, ctx: _Ctx) -> _Plan | None:
    mod = _import("mmexec.drivers.dynamixel.wx250s", "kind 'wx250s'", section.value_mark("kind"), path)
    cfg = bind(mod.WX250sConfig, _without(section, "kind"), section.mark, path, ctx.problems)
    if cfg is None:
        ctx.devices["arm"] = None  # a wx250s arm whose section has problems (reported)
        return None
    bus_mod = _import("mmexec.drivers.dynamixel.bus", "kind 'wx250s'", section.value_mark("kind"), path)
    device = mod.WX250s(cfg, clock=ctx.robot.clock)
    ctx.devices["arm"] = device

    def connect() -> Any:
        try:
            device.connect()
        except bus_mod.DynamixelError as e:
            raise _connect_error(path, section.mark, str(e)) from e
        ctx.robot.add_closer(f"wx250s on {cfg.port}", device.close)
        return mod.WX250sArm(device)

    return ("arm", f"wx250s on {cfg.port}", section.mark, connect)


def _wx250s_gripper(section: YDict, path: str, ctx: _Ctx) -> _Plan | None:
    extra = [k for k in section if k != "kind"]
    for k in extra:
        ctx.problems.add(section.key_mark(k), f"{path}.{k}: unknown key (the wx250s gripper is set up in the arm section)")
    if extra:
        return None
    if "arm" not in ctx.devices:
        ctx.problems.add(section.value_mark("kind"), f"{path}.kind: 'wx250s_gripper' needs 'arm: {{kind: wx250s}}'")
        return None
    mod = _import("mmexec.drivers.dynamixel.arm", "kind 'wx250s_gripper'", section.value_mark("kind"), path)
    device = ctx.devices["arm"]
    if device is None:
        return None  # the arm section's problems are reported there
    return ("gripper", "wx250s gripper", section.mark, lambda: mod.WX250sGripper(device))


@dataclass(frozen=True)
class _HeadSection:
    """``head: {kind: wx250s_head}`` keys: ``home`` [pan, tilt] [rad], the robot's default
    head pose (skills that move the head return to it; the head is not moved at bring-up)."""

    home: tuple[float, float] = (0.0, 0.0)


def _wx250s_head(section: YDict, path: str, ctx: _Ctx) -> _Plan | None:
    """The LoCoBot's pan/tilt head: servos 10 and 11 of the ``wx250s`` arm's bus."""
    ctx.devices["head"] = None  # planned; a camera on it reports nothing more when this has problems
    cfg = bind(_HeadSection, _without(section, "kind"), section.mark, path, ctx.problems)
    if cfg is None:
        return None
    if "arm" not in ctx.devices:
        ctx.problems.add(section.value_mark("kind"),
                         f"{path}.kind: 'wx250s_head' needs 'arm: {{kind: wx250s, locobot: true}}'")
        return None
    device = ctx.devices["arm"]
    if device is None:
        return None  # the arm section's problems are reported there
    head = device.head
    if head is None:
        ctx.problems.add(section.value_mark("kind"),
                         f"{path}.kind: 'wx250s_head' needs 'locobot: true' in the arm section (servos 10, 11)")
        return None
    problem = head.limit_problem(*cfg.home)
    if problem:
        ctx.problems.add(section.value_mark("home") if "home" in section else section.mark, f"{path}.home: {problem}")
        return None
    head.home = cfg.home
    ctx.devices["head"] = head
    return ("head", f"wx250s head (servos 10, 11) on {device.config.port}", section.mark, lambda: head)


def _robotiq(section: YDict, path: str, ctx: _Ctx, *, kind: str) -> _Plan | None:
    """``robotiq_rtu`` (Modbus RTU on a serial port) or ``robotiq_urcap`` (UR socket)."""
    mark = section.value_mark("kind")
    if kind == "robotiq_rtu":
        mod = _import("mmexec.drivers.robotiq.device", f"kind {kind!r}", mark, path)
        link_type, device_type = mod.ModbusSettings, mod.RobotiqModbus
    else:
        mod = _import("mmexec.drivers.robotiq.urcap", f"kind {kind!r}", mark, path)
        link_type, device_type = mod.URCapSettings, mod.RobotiqURCap
    from mmexec.drivers.robotiq.core import DeviceSettings
    from mmexec.drivers.robotiq.errors import RobotiqError
    from mmexec.drivers.robotiq.gripper import RobotiqGripper

    @dataclass(frozen=True)
    class _Activate:
        activate: bool = True

    link_part, dev_part, act_part = _split(_without(section, "kind"), link_type, DeviceSettings, _Activate)
    link = bind(link_type, link_part, section.mark, path, ctx.problems)
    settings = bind(DeviceSettings, dev_part, section.mark, path, ctx.problems)
    act = bind(_Activate, act_part, section.mark, path, ctx.problems)
    if link is None or settings is None or act is None:
        return None
    where = f"robotiq on {link.port}" if kind == "robotiq_rtu" else f"robotiq on {link.host}:{link.port}"

    def connect() -> RobotiqGripper:
        device = device_type(link, settings, ctx.robot.clock)
        gripper = RobotiqGripper(device)
        try:
            gripper.setup(activate=act.activate)
        except RobotiqError as e:
            device.close()
            raise _connect_error(path, section.mark, str(e)) from e
        ctx.robot.add_closer(where, device.close)
        return gripper

    return ("gripper", where, section.mark, connect)


def _ur(section: YDict, path: str, ctx: _Ctx) -> _Plan | None:
    mod = _import("mmexec.drivers.ur.arm", "kind 'ur'", section.value_mark("kind"), path)
    cfg = bind(mod.URArmConfig, _without(section, "kind"), section.mark, path, ctx.problems)
    if cfg is None:
        return None
    where = f"{cfg.model} at {cfg.host}"

    def connect() -> Any:
        arm = mod.URArm(cfg, clock=ctx.robot.clock)
        try:
            arm.open()
        except mod.URConnectionError as e:
            arm.close()
            raise _connect_error(path, section.mark, str(e)) from e
        except BaseException:  # BringUpInterrupted, also before open() could close it itself
            arm.close()
            raise
        ctx.robot.add_closer(where, arm.close)
        return arm

    ctx.devices["ur_model"] = cfg.model
    return ("arm", where, section.mark, connect)


@dataclass(frozen=True)
class _MountLink:
    """Camera key next to the :class:`CameraConfig` ones: the link ``pose_in_base`` is
    relative to: ``base_link`` (fixed on the robot), ``tool0`` (a wrist camera riding on
    the arm's flange; ``pose_in_base`` is then the hand-eye calibration ``T_tool0_camera``)
    or ``head`` (on the pan/tilt head: ``pose_in_base`` is the optical frame in
    ``base_link`` at pan = tilt = 0, moved with the head's measured joints through the
    description's head chain)."""

    mount_link: str = "base_link"


_MOUNT_LINKS = ("base_link", "tool0", "head")


def _camera(section: YDict, path: str, ctx: _Ctx, *, kind: str) -> _Plan | None:
    """``uvc`` (OpenCV VideoCapture) or ``realsense`` (pyrealsense2): a
    :class:`~mmexec.drivers.camera.config.CameraConfig` plus ``kind`` and ``mount_link``."""
    from mmexec.drivers.camera.config import CameraConfig
    from mmexec.drivers.camera.errors import CameraError

    mark = section.value_mark("kind")
    mod = _import(f"mmexec.drivers.camera.{kind}", f"kind {kind!r}", mark, path)
    cfg_part, link_part = _split(_without(section, "kind"), CameraConfig, _MountLink)
    before = len(ctx.problems)
    cfg = bind(CameraConfig, cfg_part, section.mark, path, ctx.problems)
    link = bind(_MountLink, link_part, section.mark, path, ctx.problems)
    if cfg is None or link is None or len(ctx.problems) > before:
        return None
    for name, message in cfg.problems():
        ctx.problems.add(cfg_part.value_mark(name) if name in cfg_part else section.mark, f"{path}.{name}: {message}")
    if kind == "uvc" and cfg.camera_intrinsics() is None:
        ctx.problems.add(section.mark, f"{path}: a uvc camera needs 'intrinsics' (fx, fy, cx, cy) or 'hfov' [rad]")
    link_pose: Callable[[], np.ndarray] | None = None
    if link.mount_link not in _MOUNT_LINKS:
        ctx.problems.add(link_part.value_mark("mount_link"), f"{path}.mount_link: unknown link {link.mount_link!r}"
                         + (did_you_mean(link.mount_link, _MOUNT_LINKS) or f" (expected one of: {', '.join(_MOUNT_LINKS)})"))
    elif link.mount_link == "tool0":
        if "ur_model" not in ctx.devices:
            ctx.problems.add(link_part.value_mark("mount_link"),
                             f"{path}.mount_link: 'tool0' needs 'arm: {{kind: ur}}' (the arm carrying the camera)")
        else:
            link_pose = functools.partial(_ur_tool0_in_base, ctx.robot, ctx.devices["ur_model"])
    elif link.mount_link == "head":
        if "head" not in ctx.devices:
            ctx.problems.add(link_part.value_mark("mount_link"),
                             f"{path}.mount_link: 'head' needs 'head: {{kind: wx250s_head}}' (the head carrying the camera)")
        elif ctx.devices["head"] is not None:  # else the head section's problems are reported
            link_pose = functools.partial(_head_motion, ctx.robot, ctx.devices["head"].kinematics)
    if len(ctx.problems) > before:
        return None
    robot = ctx.robot
    camera_type = mod.UVCCamera if kind == "uvc" else mod.RealSenseCamera
    where = f"{kind} {cfg.device}"
    made: list[Any] = []

    def base_pose() -> np.ndarray:
        """``T_map_base`` from the base's odometry; identity on a robot without a base."""
        return robot.base.state().pose.matrix() if robot.base is not None else np.eye(4)

    def prepare() -> None:
        # construction does no I/O but needs the optional extras (pyrealsense2): checked
        # before any device is opened, so a missing package costs no bring-up
        try:
            made.append(camera_type(cfg, clock=robot.clock, base_pose=base_pose, link_pose=link_pose))
        except CameraError as e:
            raise _connect_error(path, section.mark, f"{where}: {e}") from e

    def connect() -> Any:
        if not made:
            prepare()
        camera = made[-1]
        try:
            camera.open()
        except CameraError as e:
            camera.close()
            raise _connect_error(path, section.mark, str(e)) from e
        robot.add_closer(where, camera.close)
        return camera

    ctx.prepare.append(prepare)

    return ("camera", where, section.mark, connect)


def _ur_tool0_in_base(robot: RealRobot, model: str) -> np.ndarray:
    """``T_base_tool0`` of the robot's UR arm from its latest joint state (forward
    kinematics, independent of the TCP set on the controller)."""
    from mmexec.drivers.ur import model as urmodel

    arm = robot.arm
    if arm is None:
        raise CapabilityError("the arm carrying the camera is not connected")
    q = arm.state().positions
    return arm.mount @ urmodel.T_BASELINK_BASE @ urmodel.forward_kinematics(q, model)


def _head_motion(robot: RealRobot, model: Any) -> np.ndarray:
    """How far the head's measured joints move the camera from its pan = tilt = 0 pose:
    ``T(pan, tilt) @ inv(T(0, 0))`` of the camera link (:meth:`HeadModel.motion`)."""
    head = robot.head
    if head is None:
        raise CapabilityError("the head carrying the camera is not connected")
    try:
        st = head.state()
    except Exception as e:  # no reading yet (the driver's NotConnected): the frame's pose is unknown
        raise CapabilityError(f"the head's joints are not known: {e}") from e
    return model.motion(st.pan, st.tilt)  # type: ignore[no-any-return]


@dataclass(frozen=True)
class _PoseInBase:
    """A frame's pose in ``base_link``: ``xyz`` [m], ``rpy`` [rad] (R = Rz Ry Rx)."""

    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class _LidarMount:
    """Lidar key next to the driver's config keys: ``pose_in_base``, the pose of the lidar
    frame (CCW scan angles, angle 0 along its +x) in ``base_link``. Required: a wrong
    mount misplaces every obstacle the lidar sees."""

    pose_in_base: _PoseInBase


def _rplidar(section: YDict, path: str, ctx: _Ctx) -> _Plan | None:
    """``rplidar``: a Slamtec RPLIDAR A2 on a serial port; the
    :class:`~mmexec.drivers.rplidar.device.RplidarConfig` keys plus ``pose_in_base``.
    Brought up scanning (motor on); closing stops the scan and the motor."""
    from mmexec.drivers.rplidar.device import RplidarConfig, RplidarDevice, RplidarError
    from mmexec.drivers.rplidar.lidar import RplidarLidar

    cfg_part, mount_part = _split(_without(section, "kind"), RplidarConfig, _LidarMount)
    cfg = bind(RplidarConfig, cfg_part, section.mark, path, ctx.problems)
    mount = bind(_LidarMount, mount_part, section.mark, path, ctx.problems)
    if cfg is None or mount is None:
        return None
    T_base_lidar = pose_matrix(mount.pose_in_base.xyz, mount.pose_in_base.rpy)
    where = f"rplidar on {cfg.port}"

    def connect() -> RplidarLidar:
        dev = RplidarDevice(cfg, ctx.robot.clock)
        try:
            dev.connect()
            dev.start()
        except RplidarError as e:
            dev.close()
            raise _connect_error(path, section.mark, str(e)) from e
        ctx.robot.add_closer(where, dev.close)
        return RplidarLidar(dev, T_base_lidar)

    return ("lidar", where, section.mark, connect)


#: slot -> kind -> factory (import of the driver module happens inside the factory)
DEVICE_KINDS: dict[str, dict[str, _Factory]] = {
    "base": {"kobuki": _kobuki},
    "arm": {"wx250s": _wx250s, "ur": _ur},
    "head": {"wx250s_head": _wx250s_head},
    "gripper": {
        "wx250s_gripper": _wx250s_gripper,
        "robotiq_rtu": functools.partial(_robotiq, kind="robotiq_rtu"),
        "robotiq_urcap": functools.partial(_robotiq, kind="robotiq_urcap"),
    },
    "camera": {
        "uvc": functools.partial(_camera, kind="uvc"),
        "realsense": functools.partial(_camera, kind="realsense"),
    },
    "lidar": {"rplidar": _rplidar},
}

_TOP_KEYS = ("name", "description", "base", "arm", "gripper", "head", "camera", "lidar", "map", "scene")


# --------------------------------------------------------------------------- build


def build(
    section: YDict | None,
    *,
    profile: Mapping[str, Any],
    seed: int | None,
    options: Mapping[str, Any],
) -> RealRobot:
    """Backend builder for ``backend: robot`` (see the module doc).

    ``seed`` has no effect on real hardware; ``options`` (``gui``, ``record``) neither.
    Raises :class:`InputError` for a bad section (all problems at once, before any port
    is opened) and :class:`DeviceUnavailable` for a device that cannot be brought up.
    """
    robot, plans, ctx = _plan(section, profile)
    for step in ctx.prepare:
        step()
    try:
        with _halt_signals_abort():
            for slot, label, _mark, connect in plans:
                log.info("robot: bringing up %s: %s", slot, label)
                setattr(robot, slot, connect())
    except BaseException:
        robot.close()
        raise
    return robot


#: the signals that end a device bring-up at once (the runner's halting signals)
_BRING_UP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextlib.contextmanager
def _halt_signals_abort() -> Iterator[None]:
    """While devices come up, SIGINT, SIGTERM and SIGHUP end the bring-up at once with
    :class:`BringUpInterrupted` (``build`` closes what was opened), after the handler
    installed before has run (the runner's records the signal, which fixes the exit code
    at 128 + its number). That handler only records the signal for a tree that does not
    exist yet, so a device waiting out its connect deadline (a UR controller that never
    answers: up to ``connect_timeout``) would otherwise keep the signal waiting. Only the
    first signal raises: a second one while what was opened is closed is passed on to the
    previous handler alone, so the closing completes. Main thread only; a signal whose
    handler is not a Python function (ignored, e.g. SIGHUP under ``nohup``, or the
    default) is left alone."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.getsignal(sig) for sig in _BRING_UP_SIGNALS}
    fired: list[int] = []

    def chain(handler: Callable[[int, Any], Any]) -> Callable[[int, Any], None]:
        def on_signal(signum: int, frame: Any) -> None:
            handler(signum, frame)
            if not fired:
                fired.append(signum)
                raise BringUpInterrupted(signum)

        return on_signal

    installed = []
    for sig, handler in previous.items():
        if callable(handler):
            signal.signal(sig, chain(handler))
            installed.append(sig)
    try:
        yield
    finally:
        for sig in installed:
            signal.signal(sig, previous[sig])


def check(section: YDict | None, *, profile: Mapping[str, Any] | None = None) -> list[str]:
    """Validate a ``robot:`` section without opening any port: returns the devices it
    would bring up (``"base: kobuki on /dev/kobuki"``, ...) or raises InputError."""
    _robot, plans, _ctx = _plan(section, profile or {})
    return [f"{slot}: {label}" for slot, label, _m, _c in plans]


def check_navigation(section: YDict | None) -> tuple[OccupancyGrid | None, float | None]:
    """What navigation will use, found without opening any port: the section's map
    (``robot.map``, None without one) and the planned base's footprint radius [m] (its
    ``Base.radius`` once connected; None without a base). InputError as :func:`check`."""
    robot, _plans, ctx = _plan(section, {})
    return robot.occupancy, ctx.base_radius


def _plan(section: YDict | None, profile: Mapping[str, Any]) -> tuple[RealRobot, list[_Plan], _Ctx]:
    if section is None or not isinstance(section, YDict):
        mark = getattr(section, "mark", Mark("<config>", 1, 1))
        raise InputError.at(mark, "robot: missing section (expected a mapping with base / arm / gripper / camera / lidar)")
    problems = Problems()
    for key in section:
        if key not in _TOP_KEYS:
            problems.add(section.key_mark(key), f"robot.{key}: unknown key"
                         + (did_you_mean(key, _TOP_KEYS) or f" (expected one of: {', '.join(_TOP_KEYS)})"))
    name = section.get("name", "robot")
    if not isinstance(name, str):
        problems.add(section.value_mark("name"), f"robot.name: expected a string, got {name!r}")
        name = "robot"
    robot = RealRobot(name, profile)
    robot.description = _description(section, problems)
    ctx = _Ctx(robot, problems)
    plans: list[_Plan] = []
    for slot in ("base", "arm", "gripper", "head", "camera", "lidar"):
        if slot not in section:
            continue
        sub, path = section[slot], f"robot.{slot}"
        if not isinstance(sub, YDict):
            problems.add(section.value_mark(slot), f"{path}: expected a mapping with 'kind', got {sub!r}")
            continue
        kinds = DEVICE_KINDS[slot]
        kind = sub.get("kind")
        if kind is None:
            problems.add(sub.mark, f"{path}.kind: missing required key (expected one of: {', '.join(kinds)})")
            continue
        if kind not in kinds:
            problems.add(sub.value_mark("kind"), f"{path}.kind: unknown kind {kind!r}"
                         + (did_you_mean(str(kind), kinds) or f" (expected one of: {', '.join(kinds)})"))
            continue
        try:
            plan = kinds[kind](sub, path, ctx)
        except InputError as e:
            problems.extend(e.problems)
            continue
        if plan is not None:
            plans.append(plan)
    robot.occupancy = _load_map(section, problems)
    robot.scene = _load_scene(section, problems)
    problems.raise_if_any()
    return robot, plans, ctx


def _description(section: YDict, problems: Problems) -> descriptions.RobotDescription | None:
    """The robot description ``robot.description`` names (None without the key)."""
    if "description" not in section:
        return None
    name = section["description"]
    known = descriptions.names()
    if not isinstance(name, str) or name not in known:
        problems.add(section.value_mark("description"), f"robot.description: expected one of "
                     f"{', '.join(map(repr, known))}, got {name!r}" + did_you_mean(str(name), known))
        return None
    return descriptions.get(name)


def _load_map(section: YDict, problems: Problems) -> OccupancyGrid | None:
    if "map" not in section:
        return None
    before = len(problems)
    m = bind(MapSection, section["map"], section.value_mark("map"), "robot.map", problems)
    if m is None or len(problems) > before:
        return None
    where = section["map"].value_mark("yaml") if isinstance(section["map"], YDict) else section.value_mark("map")
    path = Path(m.yaml)
    if not path.is_absolute():
        path = Path(where.file).parent / path
    try:
        from mmexec.drivers.maps import load_map
    except ImportError as e:
        problems.add(where, f"robot.map.yaml: the map loader is not available ({e})")
        return None
    if not path.exists():
        problems.add(where, f"robot.map.yaml: no such file {str(path)!r}")
        return None
    try:
        return load_map(path)
    except InputError as e:
        problems.extend(e.problems)
        return None


def _load_scene(section: YDict, problems: Problems) -> tuple[SceneBox, ...]:
    if "scene" not in section:
        return ()
    boxes = bind(list[SceneBoxSection], section["scene"], section.value_mark("scene"), "robot.scene", problems)
    if not boxes:
        return ()
    return tuple(SceneBox(b.name, pose_matrix(b.xyz, b.rpy), b.size) for b in boxes if b is not None)


# --------------------------------------------------------------------------- the backend spec


def _parse(section: YDict | None) -> list[_Plan]:
    """The devices a ``robot:`` section plans to bring up (InputError as :func:`check`)."""
    return _plan(section, {})[1]


def _capabilities(plans: list[_Plan]) -> frozenset[str]:
    """The capability slots the planned devices fill (``head`` too, beyond
    :data:`~mmexec.drivers.backendspec.CAPABILITIES`)."""
    return frozenset(slot for slot, _label, _mark, _connect in plans)


def _navigation(section: YDict | None) -> NavMap | None:
    """``robot.map`` and the planned base's footprint radius; None without either."""
    grid, radius = check_navigation(section)
    if grid is None or radius is None:
        return None
    return NavMap(grid, radius, "robot.map")


#: The ``robot`` backend, as the executive's registry sees it.
BACKEND: BackendSpec[list[_Plan]] = BackendSpec(
    name="robot",
    parse_section=_parse,
    capabilities=_capabilities,
    build=build,
    navigation=_navigation,
)
