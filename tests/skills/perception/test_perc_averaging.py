from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.drivers.geometry import matrix_to_quat, quat_to_matrix
from mmexec.skills.perception.averaging import MarkerPoseEstimator, average_poses, rotation_angle


def _rand_rot(rng, scale):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    ang = rng.normal(0, scale)
    q = np.r_[axis * math.sin(ang / 2), math.cos(ang / 2)]
    return quat_to_matrix(q)


def test_quaternion_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(50):
        R = _rand_rot(rng, 2.0)
        assert np.allclose(quat_to_matrix(matrix_to_quat(R)), R, atol=1e-12)
    R = np.diag([1.0, -1.0, -1.0])  # 180 deg about x: a branch with trace < 0
    assert np.allclose(quat_to_matrix(matrix_to_quat(R)), R)


def test_average_beats_single_frames_and_rejects_outliers():
    rng = np.random.default_rng(5)
    T_true = np.eye(4)
    T_true[:3, :3] = _rand_rot(rng, 1.0)
    T_true[:3, 3] = (1.0, 2.0, 0.4)
    samples = []
    for _ in range(20):
        T = T_true.copy()
        T[:3, :3] = T_true[:3, :3] @ _rand_rot(rng, math.radians(2.0))
        T[:3, 3] += rng.normal(0, 0.005, 3)
        samples.append(T)
    bad_pos = T_true.copy()
    bad_pos[:3, 3] += (0.2, 0, 0)
    bad_rot = T_true.copy()
    bad_rot[:3, :3] = T_true[:3, :3] @ quat_to_matrix([0, 0, math.sin(0.5), math.cos(0.5)])  # 57 deg
    est = average_poses(samples + [bad_pos, bad_rot])
    assert est.used == 20 and est.rejected == 2
    assert np.linalg.norm(est.T[:3, 3] - T_true[:3, 3]) < 0.004
    assert math.degrees(rotation_angle(est.T[:3, :3], T_true[:3, :3])) < 1.0
    single = np.median([np.linalg.norm(T[:3, 3] - T_true[:3, 3]) for T in samples])
    assert np.linalg.norm(est.T[:3, 3] - T_true[:3, 3]) < single
    # averaging is invariant to quaternion sign flips (q and -q are the same rotation)
    assert np.allclose(average_poses([T_true, T_true]).T, T_true, atol=1e-9)


def test_estimator_window_and_readiness():
    est = MarkerPoseEstimator(min_samples=3, window=4)
    assert not est.ready
    with pytest.raises(ValueError):
        est.estimate()
    for k in range(6):
        T = np.eye(4)
        T[0, 3] = 0.001 * k
        est.add(T)
    assert est.ready and est.count == 4
    assert est.estimate().T[0, 3] == pytest.approx(0.001 * (2 + 3 + 4 + 5) / 4)
    with pytest.raises(ValueError):
        MarkerPoseEstimator(min_samples=5, window=3)
    with pytest.raises(ValueError):
        average_poses([])
