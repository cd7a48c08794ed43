"""The robot backend hands skills the description its config names (``robot.description``,
``Robot.description``); none without the key; an unknown name is one located problem
with a hint, found before any port is opened."""

from __future__ import annotations

from pathlib import Path

import pytest

from mmexec.config.yamlload import InputError, load_yaml_text
from mmexec.drivers import descriptions
from mmexec.drivers import robot as robot_backend


def _section(tmp_path: Path, text: str):  # type: ignore[no-untyped-def]
    path = tmp_path / "robot.yaml"
    path.write_text(text)
    return load_yaml_text(text, str(path))["robot"]


def test_the_robot_backend_takes_the_description_its_config_names(tmp_path: Path) -> None:
    section = _section(tmp_path, "robot:\n  name: lab_bot\n  description: ur5e_robotiq\n")
    robot = robot_backend.build(section, profile={}, seed=None, options={})
    try:
        assert robot.description is descriptions.get("ur5e_robotiq")
    finally:
        robot.close()
    section = _section(tmp_path, "robot:\n  name: lab_bot\n")
    robot = robot_backend.build(section, profile={}, seed=None, options={})
    try:
        assert robot.description is None
    finally:
        robot.close()


def test_an_unknown_description_is_one_located_problem(tmp_path: Path) -> None:
    section = _section(tmp_path, "robot:\n  name: lab_bot\n  description: locobot_wx250\n")
    with pytest.raises(InputError) as ei:
        robot_backend.check(section)
    known = ", ".join(map(repr, descriptions.names()))  # every registered robot, in registry order
    assert str(ei.value) == (f"{tmp_path / 'robot.yaml'}:3:16: robot.description: expected one of "
                             f"{known}, got 'locobot_wx250'; did you mean 'locobot_wx250s'?")
