"""The particle filter on the synthetic room: tracking, reflectors, kidnapping, KLD."""

from __future__ import annotations

import math

import numpy as np
import pytest
from locroom import POST_R, POSTS, Lidar, grid

from mmexec.drivers.geometry import wrap_angle as wrap
from mmexec.skills.localization import (
    AmclConfig,
    BeamModel,
    OdometryNoise,
    ParticleFilter,
    ReflectorConfig,
)
from mmexec.skills.localization.amcl import kld_sample_count

GOALS = [(4.5, 1.0), (4.5, 3.0), (1.0, 3.0), (1.0, 1.0)]


def _drive(pf: ParticleFilter, steps: int, seed: int, kidnap_at: int | None = None) -> np.ndarray:
    """Drive the room's loop with slipping odometry; per step (position error [m],
    heading error [rad]) of the localised pose T_map_odom * odom against the truth."""
    rng = np.random.default_rng(seed)
    lidar = Lidar(sigma=0.01)
    truth = np.array([1.0, 1.0, 0.0])
    odom = truth.copy()
    gi, out = 0, []
    for k in range(steps):
        gx, gy = GOALS[gi % len(GOALS)]
        if math.hypot(gx - truth[0], gy - truth[1]) < 0.1:
            gi += 1
        dth = float(wrap(math.atan2(gy - truth[1], gx - truth[0]) - truth[2]))
        v, w = (0.0 if abs(dth) > 0.3 else 0.05), float(np.clip(dth, -0.2, 0.2))
        truth = truth + [v * math.cos(truth[2]), v * math.sin(truth[2]), w]
        ov, ow = v * 1.03 + rng.normal(0, 0.002), w * 0.97 + 0.003  # scale error, gyro bias
        odom = odom + [ov * math.cos(odom[2]), ov * math.sin(odom[2]), ow]
        if k == kidnap_at:
            truth = np.array([4.0, 3.0, 2.0])
        r, inten = lidar.scan(truth, rng)
        pf.update(odom, r, lidar.angles, lidar.range_max, inten)
        m = pf.map_to_odom()
        x, y, _ = m @ np.array([odom[0], odom[1], 1.0])
        th = math.atan2(m[1, 0], m[0, 0]) + odom[2]
        out.append((math.hypot(x - truth[0], y - truth[1]), abs(float(wrap(th - truth[2])))))
    return np.array(out)


def _filter(reflectors: bool, seed: int = 0) -> ParticleFilter:
    cfg = AmclConfig(
        reflectors=ReflectorConfig(post_radius=POST_R) if reflectors else None,
        update_min_d=0.05,
        update_min_a=0.1,
        beams=BeamModel(sigma_hit=0.05),
        # _drive's odometry is poor (3 % scale error, a gyro bias of 3.4 deg per metre):
        # the motion model must spread the particles over that much error per update
        odometry=OdometryNoise(0.05, 0.05, 0.05, 0.05),
    )
    return ParticleFilter(grid(), cfg, reflectors=POSTS, rng=np.random.default_rng(seed))


@pytest.mark.parametrize(("reflectors", "bound"), [(False, 0.15), (True, 0.015)])
def test_tracks_the_robot_against_drifting_odometry(reflectors, bound):
    pf = _filter(reflectors)
    pf.initialise((1.2, 0.85, 0.1))  # 25 cm and 0.1 rad off
    err = _drive(pf, 300, seed=1)
    late = err[150:]
    assert late[:, 0].mean() < bound
    assert late[:, 1].mean() < 0.03
    assert pf.estimate().converged


def test_odometry_alone_drifts_far_beyond_the_filter():
    pf = _filter(True)
    pf.initialise((1.0, 1.0, 0.0), sigma=(1e-6, 1e-6))
    err = _drive(pf, 300, seed=1)
    # a filter that never moved its particles off odometry would show the drift:
    assert err[-1, 0] < 0.02


def test_a_kidnapped_robot_is_found_again_through_the_reflectors():
    pf = _filter(True)
    pf.initialise((1.0, 1.0, 0.0))
    err = _drive(pf, 200, seed=2, kidnap_at=120)
    assert err[119, 0] < 0.03
    assert err[120, 0] > 0.3  # the update that sees the kidnapped robot is off
    assert err[125:, 0].max() < 0.03  # and it is found again within five updates


def test_global_localisation_with_reflectors_converges_from_nothing():
    pf = _filter(True, seed=3)
    pf.global_localisation()
    assert len(pf.particles) == pf.cfg.max_particles
    err = _drive(pf, 120, seed=3)
    assert err[-20:, 0].max() < 0.03
    assert len(pf.particles) < pf.cfg.max_particles  # KLD shrank the set once converged


def test_kld_bound_grows_with_occupied_bins_and_matches_fox():
    z = 2.326
    n = kld_sample_count(np.array([2, 10, 100]), 0.01, z)
    assert list(n) == sorted(n)
    k = 100
    a = 2 / (9 * (k - 1))
    assert n[2] == math.ceil((k - 1) / 0.02 * (1 - a + math.sqrt(a) * z) ** 3)


def test_no_update_without_motion_and_refuses_an_empty_filter():
    pf = _filter(False)
    with pytest.raises(RuntimeError, match="initialise"):
        pf.update((0, 0, 0), np.ones(4), np.zeros(4), 12.0)
    pf.initialise((1.0, 1.0, 0.0))
    lidar = Lidar()
    r, i = lidar.scan(np.array([1.0, 1.0, 0.0]), np.random.default_rng(0))
    assert pf.update((0.0, 0.0, 0.0), r, lidar.angles, 12.0, i)  # the first scan always updates
    assert not pf.update((0.01, 0.0, 0.0), r, lidar.angles, 12.0, i)  # 1 cm: below update_min_d
