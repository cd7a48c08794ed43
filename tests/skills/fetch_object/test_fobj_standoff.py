"""Where the fetch_object mission stands to grasp: the support's free side from the map."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.skills.base import SkillContext
from mmexec.skills.fetch_object.skills import support_normal


def _ctx() -> SkillContext:
    data = np.zeros((60, 80), dtype=np.int8)  # 4 x 3 m at 5 cm
    data[0:14, 30:50] = 100                   # a table: x 1.5..2.5, y 0..0.7 (against the south wall)
    grid = OccupancyGrid(data, 0.05, Pose2D(0.0, 0.0, 0.0))
    robot = SimpleNamespace(occupancy=grid)
    return SkillContext(robot=robot, clock=SimpleNamespace(now=lambda: 0.0))  # type: ignore[arg-type]


@pytest.mark.parametrize(("xy", "camera", "expect"), [
    ((2.0, 0.6), (2.0, 1.5), (0.0, 1.0)),     # near the north edge, seen from the north: stand north of it
    ((2.42, 0.3), (3.5, 0.3), (1.0, 0.0)),    # near the east edge, seen from the east
    ((1.55, 0.35), (0.5, 0.5), (-1.0, 0.0)),  # near the west edge, seen from the west
    ((2.0, 0.45), (2.0, 1.5), (0.0, 1.0)),    # the south wall is nearer, but the camera saw it from the north
])
def test_the_normal_points_out_of_the_supports_nearest_edge_on_the_cameras_side(
        xy: tuple[float, float], camera: tuple[float, float], expect: tuple[float, float]) -> None:
    n = support_normal(_ctx(), np.array(xy), np.array(camera))
    assert n == pytest.approx(expect, abs=0.15)
    assert np.hypot(*n) == pytest.approx(1.0)


def test_an_object_on_the_open_floor_is_faced_from_the_camera() -> None:
    n = support_normal(_ctx(), np.array([3.0, 2.0]), np.array([3.0, 1.0]))
    assert n == pytest.approx((0.0, -1.0))
