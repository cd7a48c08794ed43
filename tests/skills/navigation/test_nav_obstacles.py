"""Obstacles from the lidar: scan to map points, clustering, covering circles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.drivers.interfaces import LaserScan, OccupancyGrid, Pose2D
from mmexec.skills.navigation.obstacles import (
    ObstacleConfig,
    cluster_points,
    detect_obstacles,
    fit_circles,
    scan_to_map,
)
from mmexec.skills.navigation.synthetic import cast_scan


def _scan(ranges, angle_min=-math.pi, inc=None, T=None, range_max=8.0):
    r = np.asarray(ranges, dtype=float)
    inc = 2 * math.pi / len(r) if inc is None else inc
    return LaserScan(angle_min=angle_min, angle_increment=inc, ranges=r, range_min=0.15,
                     range_max=range_max, stamp=0.0, T_base_lidar=np.eye(4) if T is None else T)


def test_scan_to_map_places_hits_in_map_frame():
    # four beams (-pi, -pi/2, 0, pi/2) from a base at (1, 2) facing +y
    scan = _scan([1.0, 2.0, np.inf, np.nan])
    pts = scan_to_map(scan, Pose2D(1.0, 2.0, math.pi / 2), clear_range=3.0)
    assert pts.hit.tolist() == [True, True, False, False]
    np.testing.assert_allclose(pts.xy[0], [1.0, 1.0], atol=1e-12)   # behind the base: -y in map
    np.testing.assert_allclose(pts.xy[1], [3.0, 2.0], atol=1e-12)   # to its right: +x in map
    assert np.isnan(pts.xy[2]).all() and np.isnan(pts.xy[3]).all()
    # free space: a hit's range, a no-return clears to clear_range, nan sees nothing
    np.testing.assert_allclose(pts.free, [1.0, 2.0, 3.0, 0.0])
    assert pts.full_circle


def test_scan_to_map_below_range_min_is_neither_hit_nor_free():
    pts = scan_to_map(_scan([0.05, 1.0, 9.0, 1.0]), Pose2D(), clear_range=4.0)
    assert pts.hit.tolist() == [False, True, False, True]
    assert pts.free.tolist() == [0.0, 1.0, 4.0, 1.0]   # 9 m >= range_max: no return


@pytest.mark.parametrize("upside_down", [False, True])
def test_beam_towards_finds_the_beam_through_a_point(upside_down):
    T = np.eye(4)
    T[:3, 3] = (0.1, -0.05, 0.3)
    if upside_down:  # rolled 180 degrees about x: the scan turns clockwise in the base frame
        T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    n = 360
    scan = _scan(np.full(n, 2.0), T=T)
    pose = Pose2D(0.5, -0.4, 0.7)
    pts = scan_to_map(scan, pose, clear_range=4.0)
    rng = np.random.default_rng(3)
    idx = rng.integers(0, n, 50)
    # points along the chosen beams, at various distances
    targets = pts.origin + pts.directions[idx] * rng.uniform(0.3, 3.0, (50, 1))
    beam, ok = pts.beam_towards(targets)
    assert ok.all()
    np.testing.assert_array_equal(beam, idx)


def test_beam_towards_outside_a_partial_scan():
    scan = _scan(np.full(91, 2.0), angle_min=-math.pi / 4, inc=math.pi / 2 / 90)  # +-45 degrees
    pts = scan_to_map(scan, Pose2D(), clear_range=4.0)
    assert not pts.full_circle
    beam, ok = pts.beam_towards(np.array([[1.0, 0.0], [1.0, 0.99], [-1.0, 0.0], [0.0, -1.0]]))
    assert ok.tolist() == [True, True, False, False]
    assert beam[0] == 45 and beam[1] == 90


def test_cluster_points_splits_on_gaps_and_chunks_long_runs():
    a = np.column_stack([np.linspace(0, 0.2, 5), np.zeros(5)])            # 0.2 m object
    b = a + [1.0, 0.0]                                                    # 0.8 m further on
    wall = np.column_stack([np.linspace(3, 5, 41), np.ones(41)])           # 2 m of new wall
    labels = cluster_points(np.vstack([a, b, wall]), gap=0.2, max_radius=0.4)
    assert labels[:5].tolist() == [0] * 5 and labels[5:10].tolist() == [1] * 5
    wall_labels = labels[10:]
    assert len(set(wall_labels)) == 3                                      # 2 m in chunks of <= 0.8 m
    for lab in set(wall_labels):
        seg = wall[wall_labels == lab]
        assert np.ptp(seg[:, 0]) <= 0.8 + 1e-9


def test_cluster_points_joins_across_the_scan_seam():
    ang = np.linspace(-0.1, 0.1, 9)
    arc = np.column_stack([2 * np.cos(ang), 2 * np.sin(ang)])
    far = np.array([[-2.0, 0.0], [-2.0, 0.05]])
    xy = np.vstack([arc[4:], far, arc[:4]])         # the object straddles the first/last beam
    assert len(set(cluster_points(xy, 0.2, 0.4, wrap=False))) == 3
    labels = cluster_points(xy, 0.2, 0.4, wrap=True)
    assert len(set(labels)) == 2 and labels[0] == labels[-1]


def test_fit_circles_cover_their_points_and_add_the_robot():
    cfg = ObstacleConfig(min_points=3, robot_radius=0.2, margin=0.05, min_radius=0.05)
    rng = np.random.default_rng(1)
    clusters = [rng.normal(c, 0.05, (12, 2)) for c in ([1.0, 1.0], [3.0, -1.0])]
    lone = np.array([[5.0, 5.0], [5.01, 5.0]])     # too few points: dropped
    xy = np.vstack(clusters + [lone])
    labels = np.repeat([0, 1, 2], [12, 12, 2])
    c = fit_circles(xy, labels, cfg)
    assert len(c) == 2
    for i, pts in enumerate(clusters):
        np.testing.assert_allclose(c.centres[i], pts.mean(axis=0))
        d = np.hypot(*(pts - c.centres[i]).T)
        assert c.radii[i] == pytest.approx(max(d.max(), 0.05))
    np.testing.assert_allclose(c.safety_radii, c.radii + 0.25)
    assert (c.velocities == 0).all() and (c.ids == -1).all() and not c.person.any()


def test_detect_obstacles_finds_circles_seen_by_the_lidar():
    grid = OccupancyGrid(data=np.zeros((100, 100), dtype=np.int8), resolution=0.05)
    centres = np.array([[3.0, 2.5], [1.0, 4.0], [4.2, 4.2]])
    radii = np.array([0.15, 0.2, 0.1])
    scan = cast_scan(grid, Pose2D(2.0, 2.0, 0.3), centres, radii, n_beams=720, range_max=6.0)
    pts = scan_to_map(scan, Pose2D(2.0, 2.0, 0.3), clear_range=4.0)
    cfg = ObstacleConfig()
    circles = detect_obstacles(pts, np.ones(pts.n_beams, dtype=bool), cfg)
    assert len(circles) == 3
    for c, r in zip(centres, radii):
        i = int(np.argmin(np.hypot(*(circles.centres - c).T)))
        # the visible side's centroid lies in front of the centre, within the radius
        assert np.hypot(*(circles.centres[i] - c)) < r
        # the covering circle holds every point the lidar saw on that object
        seen = pts.xy[pts.hit & (np.hypot(*(np.nan_to_num(pts.xy) - c).T) < r + 0.01)]
        assert (np.hypot(*(seen - circles.centres[i]).T) <= circles.radii[i] + 1e-9).all()


def test_obstacle_config_validation():
    assert ObstacleConfig().validate() == []
    errs = ObstacleConfig(cluster_gap=0.0, min_points=0, min_radius=0.5, max_radius=0.4).validate()
    assert len(errs) == 3
