"""Tracking obstacle circles: velocity estimates, people told from furniture."""

from __future__ import annotations

import numpy as np
import pytest

from mmexec.skills.navigation.obstacles import Circles
from mmexec.skills.navigation.tracks import ObstacleTracker, TrackingConfig


def _det(centres, radius=0.15):
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    n = c.shape[0]
    r = np.full(n, radius)
    return Circles(c, r, r + 0.23, np.zeros((n, 2)), np.full(n, -1), np.zeros(n, dtype=bool))


def test_constant_velocity_is_estimated_and_becomes_a_person():
    trk = ObstacleTracker()
    rng = np.random.default_rng(0)
    vel = np.array([0.8, -0.3])
    dt = 0.1
    for k in range(40):
        z = np.array([1.0, 2.0]) + vel * k * dt + rng.normal(0, 0.01, 2)  # 1 cm centroid noise
        out = trk.update(_det(z), k * dt)
    assert len(out) == 1 and out.person[0]
    np.testing.assert_allclose(out.velocities[0], vel, atol=0.05)
    np.testing.assert_allclose(out.centres[0], [1.0, 2.0] + vel * 39 * dt, atol=0.03)


def _walk_until_person(trk, extra=lambda k: []):
    """Feed a person walking at 0.6 m/s (plus ``extra(k)`` detections) until it is
    confirmed; returns the tick k of that update and its output."""
    for k in range(60):
        out = trk.update(_det([[0.6 * k * 0.1, 0.0], *extra(k)]), k * 0.1)
        if out.person.any():
            return k, out
    raise AssertionError("never confirmed")


def test_a_person_confirmed_while_tracks_come_and_go(caplog):
    """The update that confirms a person also starts two tracks and drops one."""
    kc, _ = _walk_until_person(ObstacleTracker(TrackingConfig(max_age=0.25)))
    caplog.set_level("DEBUG", logger="mmexec.skills.navigation.tracks")
    # a chair last seen 0.3 s before kc (expires at kc), two new posts appearing at kc
    extra = lambda k: ([[5.0, 5.0]] if k <= kc - 3 else []) + ([[-3.0, 2.0], [-3.0, -2.0]] if k >= kc else [])
    k, out = _walk_until_person(ObstacleTracker(TrackingConfig(max_age=0.25)), extra)
    assert k == kc and out.person.sum() == 1 and len(out) == 3
    assert "classified as people" in caplog.text


def test_furniture_with_a_wandering_centroid_stays_furniture():
    """A chair whose visible side changes: the centroid jumps by up to 10 cm between scans
    (speeds well over moving_speed for a few scans) but never leaves the chair."""
    trk = ObstacleTracker()
    rng = np.random.default_rng(1)
    for k in range(200):
        z = np.array([3.0, 1.0]) + rng.uniform(-0.1, 0.1, 2)
        out = trk.update(_det(z, radius=0.25), k * 0.05)
    assert len(out) == 1 and not out.person[0]
    assert (out.velocities == 0).all()  # only people report a velocity
    assert np.hypot(*trk.velocities()[0]) > 0.0  # the filter itself did see motion


def test_a_large_moving_cluster_is_not_a_person():
    trk = ObstacleTracker()
    for k in range(40):
        out = trk.update(_det([1.0 + 0.05 * k, 0.0], radius=0.6), k * 0.1)  # a pushed trolley
    assert not out.person[0]


def test_two_tracks_keep_their_identities_when_passing():
    trk = ObstacleTracker()
    ids = None
    for k in range(30):
        t = k * 0.1
        a = [0.0 + 0.5 * t, 0.0]
        b = [3.0 - 0.5 * t, 0.6]          # 0.6 m apart laterally, crossing at t = 3 s
        out = trk.update(_det([a, b]), t)
        order = np.argsort(out.ids)
        if ids is None:
            ids = out.ids[order].tolist()
        assert out.ids[order].tolist() == ids
        np.testing.assert_allclose(out.centres[order][0], a, atol=0.05)


def test_unseen_tracks_coast_then_expire():
    cfg = TrackingConfig(max_age=0.3)
    trk = ObstacleTracker(cfg)
    for k in range(30):
        trk.update(_det([0.05 * k, 0.0]), k * 0.1)   # 0.5 m/s: a person
    out = trk.update(_det(np.zeros((0, 2))), 3.1)
    assert len(out) == 1 and out.person[0]
    assert out.centres[0, 0] == pytest.approx(0.05 * 29 + 0.5 * 0.2, abs=0.03)  # coasted 0.2 s
    assert len(trk.update(_det(np.zeros((0, 2))), 3.5)) == 0


def test_detections_beyond_the_gate_start_new_tracks():
    trk = ObstacleTracker(TrackingConfig(gate=0.3))
    trk.update(_det([0.0, 0.0]), 0.0)
    out = trk.update(_det([1.0, 0.0]), 0.1)
    assert sorted(out.ids.tolist()) == [0, 1]


def test_time_must_not_go_back():
    trk = ObstacleTracker()
    trk.update(_det([0.0, 0.0]), 1.0)
    with pytest.raises(ValueError, match="went back"):
        trk.update(_det([0.0, 0.0]), 0.5)


def test_tracking_config_validation():
    assert TrackingConfig().validate() == []
    assert len(TrackingConfig(alpha=1.5, beta=3.5, confirm=0).validate()) == 3
    with pytest.raises(ValueError, match="TrackingConfig"):
        ObstacleTracker(TrackingConfig(gate=0.0))
