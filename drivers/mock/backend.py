"""The ``mock`` backend builder: a run config's ``mock:`` section into a :class:`MockRobot`.

Section schema (every key optional)::

    mock:
      capabilities: [base, arm, gripper, camera, lidar]   # leave some out to test needs; add
                                                           # head for a pan/tilt head carrying the camera
      base:    {start: [x, y, theta], blocked: false}      # map frame, m / rad
      arm:     {start: [q1..q6], fail_moves: [1, 2], fail_reason: "...", fail_at: 0.5,
                stop_time: 0.2}                            # rad, fraction, s
      gripper: {grasps: [false, true], default_grasp: true, object_width: 0.03,
                fault_moves: []}                           # m
      camera:  {width: 64, height: 48, hfov: 1.2, depth: 1.0, dropouts: [2]}  # px, rad, m
      lidar:   {rays: 360, range: 3.0}                     # m

Unknown keys and wrong types are :class:`~mmexec.config.yamlload.InputError` problems
located at ``FILE:LINE:COL``.

:data:`BACKEND` is its :class:`~mmexec.drivers.backendspec.BackendSpec`: the robot has the
section's ``capabilities``; no run option applies; the campaign's fault profiles script
arm, grasp, base and camera failures (:data:`FAULTS_OFF`, :data:`FAULT_PATCHES`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from mmexec.config.yamlload import Mark, Problems, YDict, bind
from mmexec.drivers.backendspec import BackendSpec
from mmexec.drivers.interfaces import Pose2D
from mmexec.drivers.mock.robot import (
    DEFAULT_ARM_LIMITS,
    MockArm,
    MockBase,
    MockCamera,
    MockGripper,
    MockLidar,
    MockRobot,
)

__all__ = ["BACKEND", "FAULTS_OFF", "FAULT_PATCHES", "MockConfig", "build", "parse_section", "robot_from_config"]

Capability = Literal["base", "arm", "gripper", "camera", "lidar", "head"]


@dataclass(frozen=True)
class MockBaseConfig:
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    blocked: bool = False


@dataclass(frozen=True)
class MockArmConfig:
    start: list[float] | None = None
    fail_moves: list[int] = field(default_factory=list)
    fail_reason: str = "trajectory aborted: joint following error"
    fail_at: float = 0.5
    stop_time: float = 0.2

    def validate(self) -> list[str]:
        out = []
        if self.start is not None and len(self.start) != len(DEFAULT_ARM_LIMITS):
            out.append(f"start: expected {len(DEFAULT_ARM_LIMITS)} joint values, got {len(self.start)}")
        if any(i < 1 for i in self.fail_moves):
            out.append("fail_moves: move numbers start at 1")
        if not 0.0 < self.fail_at <= 1.0:
            out.append(f"fail_at: expected a fraction in (0, 1], got {self.fail_at}")
        if self.stop_time < 0.0:
            out.append(f"stop_time: expected seconds >= 0, got {self.stop_time}")
        return out


@dataclass(frozen=True)
class MockGripperConfig:
    grasps: list[bool] = field(default_factory=list)
    default_grasp: bool = True
    object_width: float = 0.03
    fault_moves: list[int] = field(default_factory=list)

    def validate(self) -> list[str]:
        return [] if 0.0 <= self.object_width <= 0.085 else [f"object_width: {self.object_width} m outside [0, 0.085]"]


@dataclass(frozen=True)
class MockCameraConfig:
    width: int = 64
    height: int = 48
    hfov: float = 1.2
    depth: float = 1.0
    dropouts: list[int] = field(default_factory=list)

    def validate(self) -> list[str]:
        out = []
        if self.width < 1 or self.height < 1:
            out.append("width/height: expected positive pixel counts")
        if not 0.0 < self.hfov < 3.1:
            out.append(f"hfov: expected radians in (0, 3.1), got {self.hfov}")
        return out


@dataclass(frozen=True)
class MockLidarConfig:
    rays: int = 360
    range: float = 3.0

    def validate(self) -> list[str]:
        return [] if self.rays >= 1 else ["rays: expected at least 1"]


@dataclass(frozen=True)
class MockConfig:
    """The ``mock:`` config section (see the module doc)."""

    capabilities: list[Capability] = field(default_factory=lambda: ["base", "arm", "gripper", "camera", "lidar"])
    base: MockBaseConfig = field(default_factory=MockBaseConfig)
    arm: MockArmConfig = field(default_factory=MockArmConfig)
    gripper: MockGripperConfig = field(default_factory=MockGripperConfig)
    camera: MockCameraConfig = field(default_factory=MockCameraConfig)
    lidar: MockLidarConfig = field(default_factory=MockLidarConfig)


def parse_section(section: YDict | None, *, mark: Mark | None = None) -> MockConfig:
    """Bind a ``mock:`` section; raises InputError listing every problem."""
    problems = Problems()
    where = getattr(section, "mark", None) or mark or Mark("<config>", 1, 1)
    cfg = bind(MockConfig, section, where, "mock", problems)
    problems.raise_if_any()
    assert isinstance(cfg, MockConfig)
    return cfg


def robot_from_config(cfg: MockConfig, *, profile: Mapping[str, Any] | None = None) -> MockRobot:
    """A :class:`MockRobot` with the scripted behaviour of ``cfg`` (no I/O)."""
    robot = MockRobot(profile=profile, capabilities=cfg.capabilities)
    clock = robot.clock
    if robot.base is not None:
        robot.base = MockBase(clock, start=Pose2D(*cfg.base.start), blocked=cfg.base.blocked)
    if robot.arm is not None:
        a = cfg.arm
        robot.arm = MockArm(clock, start=a.start, fail_moves=a.fail_moves, fail_reason=a.fail_reason,
                            fail_at=a.fail_at, stop_time=a.stop_time)
    if robot.gripper is not None:
        g = cfg.gripper
        robot.gripper = MockGripper(clock, grasps=g.grasps, default_grasp=g.default_grasp,
                                    object_width=g.object_width, fault_moves=g.fault_moves)
    if robot.camera is not None:
        c = cfg.camera
        robot.camera = MockCamera(clock, robot.base, width=c.width, height=c.height, hfov=c.hfov,
                                  depth=c.depth, dropouts=c.dropouts, head=robot.head)
    if robot.lidar is not None:
        robot.lidar = MockLidar(clock, rays=cfg.lidar.rays, range=cfg.lidar.range)
    return robot


def build(
    section: YDict | None,
    *,
    profile: Mapping[str, Any],
    seed: int | None,
    options: Mapping[str, Any],
) -> MockRobot:
    """Backend builder for ``backend: mock``. The mock is deterministic, so ``seed`` only
    documents the run; ``options`` (``gui``, ``record``) have no effect on it."""
    return robot_from_config(parse_section(section), profile=profile)


def capabilities(cfg: MockConfig) -> frozenset[str]:
    """The capabilities a mock built from ``cfg`` has: those its section lists."""
    return frozenset(cfg.capabilities)


#: Merge patch of the ``mock:`` section that removes every scripted failure: arm moves
#: that fail, scripted grasps, gripper faults, a blocked base, camera dropouts.
FAULTS_OFF: dict[str, Any] = {"arm": {"fail_moves": None}, "gripper": {"grasps": None, "fault_moves": None},
                              "base": {"blocked": None}, "camera": {"dropouts": None}}

#: Built-in fault profile (``mmexec campaign --faults``) -> the failure it scripts, on
#: top of :data:`FAULTS_OFF`: arm attempts fail as grasps that close on nothing.
FAULT_PATCHES: dict[str, dict[str, Any]] = {
    "arm_fail_first": {"gripper": {"grasps": [False]}},
    "arm_fail_second": {"gripper": {"grasps": [True, False]}},
    "arm_fail_twice": {"gripper": {"grasps": [False, False]}},
    "arm_fail_always": {"gripper": {"default_grasp": False}},
    "nav_blocked": {"base": {"blocked": True}},
}

#: The ``mock`` backend, as the executive's registry sees it.
BACKEND: BackendSpec[MockConfig] = BackendSpec(
    name="mock",
    parse_section=parse_section,
    capabilities=capabilities,
    build=build,
    faults_off=FAULTS_OFF,
    fault_patches=FAULT_PATCHES,
)
