"""The mock and sim backends hand skills the active robot's description
(``Robot.description``): the mock its LoCoBot-like arm's, the sim the one ``sim.robot``
names; an unknown name is one located problem with a hint."""

from __future__ import annotations

import pytest

from mmexec.config.yamlload import InputError
from mmexec.drivers import descriptions
from mmexec.drivers.mock.robot import MockRobot
from mmexec.sim.backend import parse_section


def test_the_mock_robot_is_described_as_the_locobot_unless_told() -> None:
    robot = MockRobot()
    assert robot.description is descriptions.get("locobot_wx250s")
    assert robot.arm is not None and robot.description.info.arm_joints == tuple(robot.arm.joint_names)
    assert MockRobot(description=None).description is None
    ur = descriptions.get("ur5e_robotiq")
    assert MockRobot(description=ur).description is ur


def test_sim_robot_names_a_registered_description() -> None:
    assert parse_section({"robot": "ur5e_robotiq"}).robot == "ur5e_robotiq"
    assert parse_section(None).robot == "locobot_wx250s"
    known = ", ".join(repr(n) for n in descriptions.names())  # every registered robot
    with pytest.raises(InputError) as ei:
        parse_section({"robot": "ur5e_robotic"})
    assert str(ei.value).endswith(f"sim.robot: expected one of {known}, got 'ur5e_robotic'; "
                                  "did you mean 'ur5e_robotiq'?")
