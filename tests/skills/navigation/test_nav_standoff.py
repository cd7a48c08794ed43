from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.drivers.interfaces import OccupancyGrid
from mmexec.skills.navigation.grid import inflate
from mmexec.skills.navigation.standoff import find_standoff, standoff_pose


def _marker(x, y, z, yaw_normal):
    """A marker on a vertical face whose outward normal points along yaw_normal."""
    n = np.array([math.cos(yaw_normal), math.sin(yaw_normal), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    xr = np.cross(up, n)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = xr, up, n, (x, y, z)
    return T


def test_standoff_faces_marker_along_normal():
    T = _marker(2.0, 1.0, 0.3, math.pi)  # marker faces -x
    p = standoff_pose(T, 0.5)
    assert (p.x, p.y) == pytest.approx((1.5, 1.0))
    assert p.theta == pytest.approx(0.0)
    p = standoff_pose(_marker(0.0, 0.0, 0.3, math.pi / 2), 0.6, angle_offset=math.pi / 2)
    assert (p.x, p.y) == pytest.approx((-0.6, 0.0), abs=1e-12)
    assert p.theta == pytest.approx(0.0, abs=1e-12)


def test_vertical_normal_rejected():
    T = np.eye(4)
    with pytest.raises(ValueError):
        standoff_pose(T, 0.5)
    assert not find_standoff(inflate(OccupancyGrid(np.zeros((5, 5), np.int8), 0.1), 0.1), T, [0.5]).ok


def test_find_standoff_tries_alternatives_and_reports_failure():
    data = np.zeros((60, 60), dtype=np.int8)
    data[:, 40:] = 100              # shelf / wall the marker is on, at x >= 2.0
    data[27:33, 28:31] = 100        # an obstacle right where the 0.5 m stand-off would be
    cm = inflate(OccupancyGrid(data, 0.05), 0.18)
    T = _marker(2.0, 1.5, 0.3, math.pi)
    r = find_standoff(cm, T, [0.5, 0.8], start=(0.3, 1.5))
    assert r.ok and r.path is not None
    assert cm.is_free(r.pose.x, r.pose.y)
    assert r.tried and r.tried[0][2] == "pose in collision or off the map"
    # facing the marker
    assert math.atan2(1.5 - r.pose.y, 2.0 - r.pose.x) == pytest.approx(r.pose.theta)
    # everything blocked
    r = find_standoff(cm, T, [0.05, 0.1], angle_offsets=(0.0,))
    assert not r.ok and "no free stand-off" in r.reason and len(r.tried) == 2


def test_find_standoff_requires_path_when_start_given():
    data = np.zeros((40, 40), dtype=np.int8)
    data[:, 20] = 100
    cm = inflate(OccupancyGrid(data, 0.05), 0.1)
    T = _marker(1.8, 1.0, 0.3, math.pi)
    r = find_standoff(cm, T, [0.5], start=(0.2, 1.0))
    assert not r.ok and r.tried[0][2] == "no path from start"
    assert find_standoff(cm, T, [0.5]).ok
