"""mmexec.drivers.geometry: the one angle wrap, SE(2) / SE(3) transforms, quaternions and
the rigid fit that skills, the simulator and the drivers share."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.drivers.geometry import (
    matrix_to_quat,
    planar_transform,
    position_quat,
    quat_to_matrix,
    rigid_fit,
    rot_x,
    rot_y,
    rot_z,
    rpy_matrix,
    se2_matrix,
    wrap_angle,
    xyz_rpy_transform,
)
from mmexec.drivers.interfaces import Pose2D


@pytest.mark.parametrize("a, wrapped", [
    (0.0, 0.0), (math.pi, -math.pi), (-math.pi, -math.pi), (3 * math.pi / 2, -math.pi / 2),
    (-3 * math.pi / 2, math.pi / 2), (7.0, 7.0 - 2 * math.pi), (-20.0, -20.0 + 6 * math.pi),
])
def test_wrap_angle_lands_in_minus_pi_to_pi(a: float, wrapped: float) -> None:
    assert wrap_angle(a) == pytest.approx(wrapped, abs=1e-12)
    assert -math.pi <= wrap_angle(a) < math.pi


def test_wrap_angle_is_the_formula_every_copy_used_bit_for_bit() -> None:
    """Seeded runs must not change: the shared wrap gives exactly what the copies gave."""
    rng = np.random.default_rng(0)
    for a in rng.uniform(-30.0, 30.0, 1000):
        assert wrap_angle(float(a)) == (float(a) + math.pi) % (2.0 * math.pi) - math.pi


def test_wrap_angle_works_element_wise_on_arrays() -> None:
    a = np.array([0.5, 4.0, -4.0, 10.0])
    out = wrap_angle(a)
    assert isinstance(out, np.ndarray)
    assert out == pytest.approx([wrap_angle(float(x)) for x in a], abs=0.0)


def test_planar_transforms_agree_with_pose2d() -> None:
    x, y, th = 1.2, -0.4, 2.5
    T = planar_transform(x, y, th, z=0.3)
    assert np.allclose(T[:3, :3], rot_z(th)) and np.allclose(T[:3, 3], [x, y, 0.3])
    assert np.array_equal(Pose2D(x, y, th).matrix(), planar_transform(x, y, th))
    S = se2_matrix(x, y, th)
    assert np.allclose(S[:2, :2], rot_z(th)[:2, :2]) and np.allclose(S[:2, 2], [x, y])
    assert np.allclose(S @ [1.0, 0.0, 1.0], (T @ [1.0, 0.0, 0.0, 1.0])[[0, 1, 3]])


def test_rpy_is_z_then_y_then_x() -> None:
    r, p, y = 0.3, -0.7, 1.9
    assert np.allclose(rpy_matrix((r, p, y)), rot_z(y) @ rot_y(p) @ rot_x(r))
    T = xyz_rpy_transform((1.0, 2.0, 3.0), (r, p, y))
    assert np.allclose(T[:3, :3], rpy_matrix((r, p, y))) and np.allclose(T[:3, 3], [1, 2, 3])


def test_quaternions_round_trip_on_every_branch() -> None:
    for R in (rot_z(0.4) @ rot_x(0.2), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]),
              np.diag([-1.0, -1.0, 1.0])):
        q = matrix_to_quat(R)
        assert q[3] >= 0 and np.linalg.norm(q) == pytest.approx(1.0)
        assert np.allclose(quat_to_matrix(q), R, atol=1e-12)
    # a 4x4 transform's rotation part is read as is
    T = xyz_rpy_transform((1.0, 0.0, 0.0), (0.1, 0.2, 0.3))
    assert np.allclose(matrix_to_quat(T), matrix_to_quat(T[:3, :3]))
    pos, quat = position_quat(T)
    assert pos == [1.0, 0.0, 0.0] and all(type(v) is float for v in pos + quat)
    assert np.allclose(quat_to_matrix(quat), T[:3, :3])


def test_rigid_fit_recovers_a_2d_and_a_3d_motion() -> None:
    rng = np.random.default_rng(1)
    src = rng.uniform(-1.0, 1.0, (6, 3))
    R = rpy_matrix((0.2, -0.4, 1.1))
    Rf, t = rigid_fit(src, src @ R.T + [0.5, -1.0, 2.0])
    assert np.allclose(Rf, R) and np.allclose(t, [0.5, -1.0, 2.0])
    R2 = rot_z(0.8)[:2, :2]
    Rf2, t2 = rigid_fit(src[:, :2], src[:, :2] @ R2.T + [0.1, 0.2])
    assert np.allclose(Rf2, R2) and np.allclose(t2, [0.1, 0.2])
