"""The simulated lidar casts its rays once per state: a second scan in the same substep
(the localiser's after a spin, then the local planner's in the next tick) reuses them and
draws its own noise; anything that moves the world (a spin, a teleport) casts again."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from mmexec.drivers.interfaces import Pose2D
from mmexec.sim.backend import build


@pytest.fixture()
def robot(sim_section, bench_world):
    sec = sim_section(f"robot: locobot_wx250s\nworld: {bench_world}\nlidar: {{noise: 0.01, beams: 360}}\n")
    r = build(sec, profile={}, seed=0, options={})
    r.spin(0.5)
    yield r
    r.close()


@pytest.fixture()
def casts(monkeypatch):
    """Counts pybullet ray batches."""
    n = [0]
    real = p.rayTestBatch

    def counting(*args, **kwargs):
        n[0] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(p, "rayTestBatch", counting)
    return n


def test_a_second_scan_in_the_same_substep_reuses_the_rays_with_fresh_noise(robot, casts):
    a, b = robot.lidar.scan(), robot.lidar.scan()
    assert a is not None and b is not None and casts[0] == 1
    assert not np.array_equal(a.ranges, b.ranges)  # noise drawn for each scan
    assert float(np.abs(a.ranges - b.ranges).max()) < 0.1  # the same rays under 1 cm noise
    np.testing.assert_array_equal(a.intensities, b.intensities)
    np.testing.assert_array_equal(a.T_base_lidar, b.T_base_lidar)
    assert a.T_base_lidar is not b.T_base_lidar


def test_a_spin_or_a_teleport_casts_again(robot, casts):
    near = robot.lidar.scan()
    robot.spin(1 / robot.clock.hz)
    robot.lidar.scan()
    assert casts[0] == 2
    robot.core.place_base(Pose2D(2.5, 1.5, 1.0))  # same clock step, base moved
    far = robot.lidar.scan()
    assert casts[0] == 3
    assert near is not None and far is not None
    assert float(np.abs(near.ranges - far.ranges).max()) > 0.3
    robot.arm.set_positions([0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    robot.lidar.scan()
    assert casts[0] == 4


def test_the_reused_rays_equal_a_fresh_cast(robot):
    """The reused rays are exactly those of a new cast of the same state."""
    robot.lidar.scan()
    again = robot.lidar._cast()
    robot.lidar._last = None
    fresh = robot.lidar._cast()
    for x, y in zip(again, fresh):
        np.testing.assert_array_equal(x, y)
