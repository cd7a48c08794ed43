"""The robot backend's ``lidar`` slot: built from a config pointing at the fake, with its
mount; located errors for a bad section and for a lidar that does not answer."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from mmexec.config.yamlload import InputError
from mmexec.drivers import robot as rb
from mmexec.drivers.fakes.rplidar import RplidarFake
from mmexec.drivers.rplidar.lidar import RplidarLidar
from mmexec.executive.config import build_robot, load_config

#: laser_frame_link in base_footprint on the LoCoBot (docs/robots.md 1.2), as config/locobot.yaml has it
MOUNT = "pose_in_base: {xyz: [-0.097997, -0.000044, 0.63693], rpy: [0.0, 0.0, 3.1415927]}"


def _config(tmp_path: Path, lidar: str) -> Path:
    p = tmp_path / "run.yaml"
    p.write_text("backend: robot\nrate_hz: 20\nrobot:\n  name: lidar_bot\n  lidar:\n" + lidar)
    return p


def test_build_scans_with_the_mount_and_close_stops_the_motor(
        tmp_path: Path, fake: RplidarFake, wait_until: Callable[..., bool]) -> None:
    cfg = _config(tmp_path, f"    kind: rplidar\n    port: {fake.port}\n    beams: 720\n    {MOUNT}\n")
    robot = build_robot(load_config(cfg))
    try:
        assert isinstance(robot.lidar, RplidarLidar) and robot.base is None
        lidar = robot.lidar
        assert wait_until(lambda: lidar.scan() is not None)
        scan = lidar.scan()
        assert scan is not None and len(scan.ranges) == 720
        T = scan.T_base_lidar
        assert T[:3, 3] == pytest.approx([-0.097997, -0.000044, 0.63693])
        assert T[:3, :3] @ np.array([1.0, 0.0, 0.0]) == pytest.approx([-1.0, 0.0, 0.0], abs=1e-6)  # yawed by pi
        assert scan.stamp <= robot.clock.now()
        # the fake's east wall, 4 m straight ahead of the lidar, is 4 m behind the base
        ahead = scan.ranges[int(np.argmin(np.abs(scan.angles)))]
        p = T @ np.array([ahead, 0.0, 0.0, 1.0])
        assert p[0] == pytest.approx(-0.098 - 4.0, abs=0.05) and math.isfinite(ahead)
    finally:
        robot.close()
    assert wait_until(lambda: not fake.motor_running and not fake.snapshot().scanning, 1.0)


def test_the_mount_is_required_and_keys_are_checked(tmp_path: Path) -> None:
    cfg = _config(tmp_path, "    kind: rplidar\n    port: /dev/rplidar\n    beam: 360\n")
    with pytest.raises(InputError) as ei:
        rb.check(load_config(cfg).section())
    text = str(ei.value)
    assert "robot.lidar.beam: unknown key" in text and "did you mean 'beams'" in text
    assert "robot.lidar.pose_in_base: missing required key" in text


def test_a_silent_lidar_is_one_located_line(tmp_path: Path, fake: RplidarFake) -> None:
    fake.silent = True
    cfg = _config(tmp_path, f"    kind: rplidar\n    port: {fake.port}\n    response_timeout: 0.2\n    {MOUNT}\n")
    with pytest.raises(InputError) as ei:   # rb.DeviceUnavailable, located by the config loader
        build_robot(load_config(cfg))
    assert str(ei.value) == (f"{cfg}:6:5: robot.lidar: rplidar on {fake.port}: no answer to GET_INFO within "
                             "0.2 s (is the lidar powered and its USB adapter plugged in?)")
