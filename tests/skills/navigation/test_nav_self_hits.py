"""The lidar's returns off the robot's own body are not obstacles (issue 12): the UR
platforms' lidar sits at the front of the base, and beams cast backwards from its minimum
range started inside the arm's base and returned off its far side, 0.05-0.1 m ahead of
the base's centre. Those hits marked the costmap under the base, the lidar never cleared
them (they lie within its minimum range), and the path ahead looked blocked for good."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.skills.navigation.costmap import RollingCostmap
from mmexec.skills.navigation.limits import UR5E_PLATFORM
from mmexec.skills.navigation.local_planner import SELF_FRACTION, LocalPlanner, LocalPlannerConfig
from mmexec.skills.navigation.obstacles import drop_within, scan_to_map
from mmexec.skills.navigation.synthetic import cast_scan

POSE = Pose2D(3.0, 3.0, math.pi / 2)
LIDAR_AHEAD = 0.26  # [m] the UR platform's lidar: 0.05 m in from the box's front face
POLE = (3.0, 4.6)   # [m] a real obstacle 1.6 m ahead of the base


def _room() -> OccupancyGrid:
    d = np.zeros((120, 120), dtype=np.int8)        # 6 x 6 m at 5 cm
    d[0, :] = d[-1, :] = d[:, 0] = d[:, -1] = 100
    return OccupancyGrid(data=d, resolution=0.05)


def _scan(self_hits: bool, pose: Pose2D = POSE):
    """A 360-degree scan from the lidar at the front of the base, seeing the pole; with
    ``self_hits`` the beams within 20 degrees of straight back return 0.2 m from the lidar
    (0.06 m ahead of the base's centre: the far side of the arm's base)."""
    T = np.eye(4)
    T[0, 3] = LIDAR_AHEAD
    scan = cast_scan(_room(), pose, np.array([POLE]), np.array([0.1]), T_base_lidar=T)
    if not self_hits:
        return scan
    back = np.abs(np.abs(scan.angles) - math.pi) < math.radians(20)
    return replace(scan, ranges=np.where(back, 0.2, scan.ranges))


def test_hits_inside_the_base_are_dropped_and_hits_outside_kept():
    pts = scan_to_map(_scan(True), POSE, 3.0)
    own = drop_within(pts, (POSE.x, POSE.y), SELF_FRACTION * UR5E_PLATFORM.radius)
    assert pts.hit.sum() - own.hit.sum() > 0                    # the self-hits were hits
    near = np.hypot(pts.xy[:, 0] - POSE.x, pts.xy[:, 1] - POSE.y) < 0.2
    assert not own.hit[near].any() and (own.free[near] == 0.0).all()
    assert (own.hit == (pts.hit & ~near)).all()                # every other hit is kept
    assert drop_within(pts, (POSE.x, POSE.y), 0.0) is pts


def test_the_planner_marks_no_self_hit_and_keeps_the_path_ahead_free():
    """Without the filter the self-hits mark the costmap under the base and the path
    straight ahead is blocked within the robot radius of them; with it, only the pole is
    marked and the way to a goal short of it is clear."""
    cfg = LocalPlannerConfig.for_base(UR5E_PLATFORM, 0.03)
    planner = LocalPlanner(_room(), cfg)
    planner.set_path([(POSE.x, POSE.y), (3.0, 3.6)], 0.0)
    for k in range(5):
        planner.observe(replace(_scan(True), stamp=0.1 * k), POSE)
    cm = planner.costmap
    marked = cm._centres_of(*np.nonzero(cm.marks))
    assert len(marked) and np.hypot(marked[:, 0] - POLE[0], marked[:, 1] - POLE[1]).max() < 0.2
    assert math.isinf(planner.dwa.path_blocked(POSE, cm, planner.circles_at(0.5)))
    # the same scans with the filter off (the raw hits): the path ahead is blocked
    raw = RollingCostmap(_room(), cfg.costmap)
    for k in range(5):
        raw.update(scan_to_map(replace(_scan(True), stamp=0.1 * k), POSE, cfg.costmap.clear_range))
    assert not math.isinf(planner.dwa.path_blocked(POSE, raw, planner.circles_at(0.5)))


def test_marks_under_the_base_are_cleared_but_not_pinned_ones():
    cm = RollingCostmap(_room())
    cm.update(scan_to_map(_scan(True, Pose2D(3.0, 2.0, math.pi / 2)), Pose2D(3.0, 2.0, math.pi / 2), 3.0))
    cm.pin(np.array([[3.0, 3.1]]))                             # a contact pinned under the base
    before = int(cm.marks.sum())
    # the base drove 1 m on: its earlier self-hits (0.06 m ahead of (3, 2)) are now 0.94 m
    # behind it and stay; marks on its own spot go, the pinned contact stays
    cm.update(scan_to_map(_scan(True), POSE, 3.0))
    under = int(cm.clear_disc((POSE.x, POSE.y), SELF_FRACTION * UR5E_PLATFORM.radius))
    assert under > 0 and int(cm.marks.sum()) >= before - under
    free = cm._centres_of(*np.nonzero(cm.marks & ~cm.pinned))
    assert not (np.hypot(free[:, 0] - POSE.x, free[:, 1] - POSE.y) <= SELF_FRACTION * UR5E_PLATFORM.radius).any()
    assert cm.pinned.any() and cm.marks[cm.pinned].all()
    left = cm._centres_of(*np.nonzero(cm.marks))
    assert (np.hypot(left[:, 0] - 3.0, left[:, 1] - 2.06) < 0.1).any()
