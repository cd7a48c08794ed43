"""The likelihood field: distance transform against brute force, and the beam model."""

from __future__ import annotations

import math

import numpy as np
import pytest
from locroom import Lidar, grid

from mmexec.drivers.interfaces import OccupancyGrid, Pose2D
from mmexec.skills.localization.likelihood import BeamModel, LikelihoodField


def test_distance_field_equals_brute_force_nearest_obstacle():
    rng = np.random.default_rng(3)
    data = np.zeros((40, 50), dtype=np.int8)
    data[rng.random(data.shape) < 0.03] = 100
    g = OccupancyGrid(data=data, resolution=0.1, origin=Pose2D(-1.0, 2.0, 0.3))
    f = LikelihoodField(g, BeamModel(max_occ_dist=10.0))
    occ = np.argwhere(data >= 65)
    for r, c in np.argwhere(np.ones_like(data, dtype=bool))[::7]:
        brute = np.min(np.hypot(occ[:, 0] - r, occ[:, 1] - c)) * 0.1
        assert f.distance[r, c] == pytest.approx(brute, abs=1e-3)


def test_distance_at_follows_the_rotated_origin_and_clamps_off_the_map():
    data = np.zeros((20, 20), dtype=np.int8)
    data[10, 15] = 100
    g = OccupancyGrid(data=data, resolution=0.1, origin=Pose2D(1.0, 1.0, math.pi / 2))
    f = LikelihoodField(g, BeamModel(max_occ_dist=0.5))
    # cell (row 10, col 15) centre: grid (1.55, 1.05) -> map (1 - 1.05, 1 + 1.55)
    assert f.distance_at(np.array([-0.05]), np.array([2.55]))[0] == pytest.approx(0.0)
    assert f.distance_at(np.array([50.0]), np.array([50.0]))[0] == 0.5


def test_the_true_pose_scores_higher_than_offset_poses():
    g = grid()
    f = LikelihoodField(g, BeamModel(sigma_hit=0.05))
    lidar = Lidar(sigma=0.01)
    truth = np.array([1.5, 1.0, 0.4])
    ranges, _ = lidar.scan(truth, np.random.default_rng(4))
    r, a = f.beam_subset(ranges, lidar.angles, lidar.range_max)
    assert len(r) == f.model.max_beams
    poses = np.array([truth, truth + [0.1, 0, 0], truth + [0, -0.1, 0], truth + [0, 0, 0.1]])
    p = f.scan_likelihood(poses, r, a, lidar.range_max)
    assert p.argmax() == 0
    # beam model: one beam exactly on an obstacle contributes (z_hit + z_rand/range_max)^3
    one = f.scan_likelihood(np.zeros((1, 3)), np.array([0.0]), np.array([0.0]), 10.0)  # end point at the origin
    d0 = f.distance_at(np.zeros(1), np.zeros(1))[0]
    m = f.model
    pz = m.z_hit * math.exp(-d0 * d0 / (2 * m.sigma_hit**2)) + m.z_rand / 10.0
    assert one[0] == pytest.approx(1.0 + pz**3)
