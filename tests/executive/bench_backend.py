"""A test-only fourth backend, ``bench``: a bench-top rig of in-memory devices (the mock's
capabilities, scripted grasps), registered through the same mechanism as mock, sim and
robot (an entry in :data:`mmexec.executive.backends.BACKENDS` naming this module), to
prove the registry is the only place a new backend touches. Section::

    bench:
      rig: [base, arm, gripper]   # the devices on the bench (default: all five)
      grasps: [false, true]       # the n-th gripper close finds an object when true
      dropouts: [2]               # camera frames that are missing (1-based)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from mmexec.config.yamlload import Mark, Problems, YDict, bind
from mmexec.drivers.backendspec import CAPABILITIES, BackendSpec
from mmexec.drivers.mock.robot import MockCamera, MockGripper, MockRobot

Device = Literal["base", "arm", "gripper", "camera", "lidar"]


@dataclass(frozen=True)
class BenchSection:
    rig: list[Device] = field(default_factory=lambda: list(CAPABILITIES))
    grasps: list[bool] = field(default_factory=list)
    dropouts: list[int] = field(default_factory=list)


def parse_section(section: YDict | None) -> BenchSection:
    problems = Problems()
    out = bind(BenchSection, section, getattr(section, "mark", Mark("<bench>", 1, 1)), "bench", problems)
    problems.raise_if_any()
    assert isinstance(out, BenchSection)
    return out


def capabilities(cfg: BenchSection) -> frozenset[str]:
    return frozenset(cfg.rig)


def build(section: YDict | None, *, profile: Mapping[str, Any], seed: int | None,
          options: Mapping[str, Any]) -> MockRobot:
    cfg = parse_section(section)
    robot = MockRobot(profile=profile, capabilities=cfg.rig, name="bench")
    if robot.gripper is not None:
        robot.gripper = MockGripper(robot.clock, grasps=cfg.grasps)
    if robot.camera is not None:
        robot.camera = MockCamera(robot.clock, robot.base, dropouts=cfg.dropouts)
    return robot


BACKEND: BackendSpec[BenchSection] = BackendSpec(
    name="bench",
    parse_section=parse_section,
    capabilities=capabilities,
    build=build,
    faults_off={"grasps": None, "dropouts": None},
    fault_patches={"arm_fail_first": {"grasps": [False]}, "arm_fail_always": {"grasps": [False, False, False]}},
)
