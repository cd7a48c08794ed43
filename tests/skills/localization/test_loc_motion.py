"""The odometry motion model: decomposition and the moments of its samples."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.skills.localization.motion import OdometryNoise, odometry_step, sample_odometry_motion


def test_noise_free_step_is_the_odometry_step_applied_in_each_particles_frame():
    prev, now = np.array([1.0, 2.0, 0.3]), np.array([1.5, 2.4, 0.9])
    particles = np.array([[0.0, 0.0, 0.0], [3.0, -1.0, math.pi / 2]])
    out = sample_odometry_motion(particles, prev, now, OdometryNoise(0, 0, 0, 0), np.random.default_rng(0))
    rot1, trans, rot2 = odometry_step(prev, now)
    for p, o in zip(particles, out, strict=True):
        h = p[2] + rot1
        assert o[0] == pytest.approx(p[0] + trans * math.cos(h))
        assert o[1] == pytest.approx(p[1] + trans * math.sin(h))
        assert o[2] == pytest.approx(p[2] + rot1 + rot2)
    # the particle at the odometry's own start lands on its end
    same = sample_odometry_motion(prev[None], prev, now, OdometryNoise(0, 0, 0, 0), np.random.default_rng(0))
    assert same[0] == pytest.approx(now)


def test_sample_moments_match_the_model():
    noise = OdometryNoise(alpha1=0.05, alpha2=0.02, alpha3=0.01, alpha4=0.01)
    prev, now = np.zeros(3), np.array([1.0, 0.0, 0.4])  # rot1 0, trans 1, rot2 0.4
    rng = np.random.default_rng(1)
    n = 200_000
    out = sample_odometry_motion(np.zeros((n, 3)), prev, now, noise, rng)
    trans = np.hypot(out[:, 0], out[:, 1])
    # sd(trans) = sqrt(a3 t^2 + a4 (rot1^2 + rot2^2))
    assert trans.mean() == pytest.approx(1.0, abs=0.01)
    assert trans.std() == pytest.approx(math.sqrt(0.01 + 0.01 * 0.16), rel=0.03)
    rot1 = np.arctan2(out[:, 1], out[:, 0])
    assert rot1.std() == pytest.approx(math.sqrt(0.02 * 1.0), rel=0.03)  # a2 t^2, rot1 = 0
    heading = out[:, 2]
    var_rot2 = 0.05 * 0.16 + 0.02
    assert heading.mean() == pytest.approx(0.4, abs=0.005)
    assert heading.std() == pytest.approx(math.sqrt(0.02 + var_rot2), rel=0.03)


def test_backward_step_is_not_a_half_turn_in_the_noise():
    noise = OdometryNoise(alpha1=0.2, alpha2=0.0, alpha3=0.0, alpha4=0.0)
    prev, now = np.zeros(3), np.array([-0.5, 0.0, 0.0])  # straight back: rot1 = pi
    out = sample_odometry_motion(np.zeros((5000, 3)), prev, now, noise, np.random.default_rng(2))
    assert np.abs(out[:, 2]).max() < 1e-9  # no rotation noise from a rot1 of pi
    assert out[:, 0] == pytest.approx(-0.5)
