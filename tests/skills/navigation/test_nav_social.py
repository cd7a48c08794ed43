"""Social layer: Gaussian cost around people and the speed limit near them."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from mmexec.skills.navigation.obstacles import Circles
from mmexec.skills.navigation.social import PeopleWait, SocialConfig, social_cost, speed_scale


def _people(centres, radius=0.2):
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    n = c.shape[0]
    return Circles(c, np.full(n, radius), np.full(n, radius + 0.23), np.zeros((n, 2)),
                   np.arange(n), np.ones(n, dtype=bool))


def test_gaussian_cost_values():
    cfg = SocialConfig(amplitude=2.0, sigma=0.5, cutoff=3.0)
    c = np.array([[1.0, 1.0]])
    pts = np.array([[1.0, 1.0], [1.5, 1.0], [1.0, 0.0], [1.0 + 1.49, 1.0], [1.0 + 1.51, 1.0]])
    got = social_cost(pts, c, cfg)
    expect = [2.0, 2.0 * math.exp(-0.5), 2.0 * math.exp(-2.0), 2.0 * math.exp(-1.49**2 / 0.5), 0.0]
    np.testing.assert_allclose(got, expect)


def test_people_combine_by_the_maximum():
    cfg = SocialConfig(amplitude=1.0, sigma=0.4)
    c = np.array([[0.0, 0.0], [0.6, 0.0]])
    mid = social_cost(np.array([[0.3, 0.0]]), c, cfg)[0]
    assert mid == pytest.approx(math.exp(-0.09 / 0.32))   # not twice that
    assert social_cost(np.zeros((3, 2)), np.zeros((0, 2)), cfg).tolist() == [0.0, 0.0, 0.0]


def test_cost_of_people_predicted_along_rollouts():
    """(k, 1, K, 2) centres against (N, K, 2) rollout points: each time step against the
    people's positions at that time."""
    cfg = SocialConfig(sigma=0.5)
    times = np.array([0.0, 1.0, 2.0])
    people = np.array([[0.0, 0.0]])[:, None, :] + times[None, :, None] * np.array([1.0, 0.0])  # (1, K, 2)
    pts = np.stack([np.column_stack([times, np.zeros(3)]),          # walks with the person
                    np.column_stack([np.zeros(3), np.zeros(3)])])   # stays where it started
    got = social_cost(pts, people[:, None], cfg)
    np.testing.assert_allclose(got[0], [1.0, 1.0, 1.0])
    np.testing.assert_allclose(got[1], [1.0, math.exp(-2.0), 0.0])


def test_speed_scale_falls_linearly_with_the_gap():
    cfg = SocialConfig(slow_gap=1.2, stop_gap=0.3, min_scale=0.3, robot_radius=0.2)
    ppl = _people([[0.0, 0.0]], radius=0.2)
    assert speed_scale((5.0, 0.0), _people(np.zeros((0, 2))), cfg) == 1.0
    assert speed_scale((0.4 + 1.2 + 0.1, 0.0), ppl, cfg) == 1.0                       # gap 1.3
    assert speed_scale((0.4 + 0.75, 0.0), ppl, cfg) == pytest.approx(0.3 + 0.7 * 0.5)  # gap 0.75
    assert speed_scale((0.4 + 0.1, 0.0), ppl, cfg) == pytest.approx(0.3)               # gap 0.1
    gaps = np.linspace(0.0, 2.0, 41)
    scales = [speed_scale((0.4 + g, 0.0), ppl, cfg) for g in gaps]
    assert all(b >= a for a, b in itertools.pairwise(scales))


def test_social_config_validation():
    assert SocialConfig().validate() == []
    assert len(SocialConfig(sigma=0.0, stop_gap=2.0, min_scale=0.0).validate()) == 3


def test_the_wait_for_people_is_bounded():
    """Someone within slow_gap: the base waits (standing time only) until the patience is
    spent; it stays spent while they stay; a stretch without anyone near starts afresh."""
    cfg = SocialConfig(slow_gap=1.2, robot_radius=0.2, patience=3.0)
    wait = PeopleWait(cfg)
    near, far = _people([[1.0, 0.0]]), _people([[5.0, 0.0]])
    t = 0.0
    assert not wait.update(far, (0.0, 0.0), t)
    answers = []
    for _ in range(80):                               # 4 s at 20 Hz with someone 0.6 m away
        t += 0.05
        answers.append(wait.update(near, (0.0, 0.0), t))
    assert all(answers[:59]) and not any(answers[61:]) and wait.spent
    assert not wait.update(far, (0.0, 0.0), t + 0.05) and not wait.spent
    # driving past people does not use the patience up
    for _ in range(200):
        t += 0.05
        assert wait.update(near, (0.0, 0.0), t, standing=False)
    assert wait.waited == 0.0
    # a clock that stood still for a while counts as one short step
    assert wait.update(near, (0.0, 0.0), t + 30.0) and wait.waited == PeopleWait.MAX_STEP
    # a new stretch (a new drive, a recovery) has its patience back
    wait.waited = 99.0
    wait.reset()
    assert not wait.spent and wait.update(near, (0.0, 0.0), t + 31.0) and wait.waited == 0.0
