"""Mock backend: in-memory capabilities with scriptable outcomes (public testing module).

A capability layer like the simulator and the real drivers, it knows nothing of skills.
To unit-test your own skills on it use the skill test kit :mod:`mmexec.skills.testing`
(``run_with_mock`` and the pytest fixtures ``mock_robot``, ``skill_ctx``,
``run_mock_skill``; docs/testing.md). In a run config, ``backend: mock`` selects this backend and the
``mock:`` section scripts it (see :mod:`mmexec.drivers.mock.backend`).
"""

from __future__ import annotations

from mmexec.drivers.mock.backend import MockConfig, build, parse_section, robot_from_config
from mmexec.drivers.mock.robot import (
    DEFAULT_ARM_LIMITS,
    MockArm,
    MockBase,
    MockCamera,
    MockGripper,
    MockHead,
    MockLidar,
    MockRobot,
)

__all__ = [
    "DEFAULT_ARM_LIMITS",
    "MockArm",
    "MockBase",
    "MockCamera",
    "MockConfig",
    "MockGripper",
    "MockHead",
    "MockLidar",
    "MockRobot",
    "build",
    "parse_section",
    "robot_from_config",
]
