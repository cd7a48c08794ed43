from __future__ import annotations

import numpy as np
import pytest

from mmexec.skills.perception.priority import Z_MAX, centroid_depth, choose_target, priority_scores


def test_score_is_the_thesis_formula():
    c = np.array([1.0, 0.5, 0.9, 0.0])
    z = np.array([0.0, 0.75, 1.5, 0.3])
    np.testing.assert_allclose(priority_scores(c, z), c / 4 + 3 / 4 * (Z_MAX - z) / Z_MAX)
    np.testing.assert_allclose(priority_scores(c, z), [1.0, 0.5, 0.225, 0.6])
    assert priority_scores(0.8, 1.0, z_max=2.0) == pytest.approx(0.2 + 0.375)


def test_nearness_outweighs_confidence():
    # 0.3 m nearer beats 0.6 more confidence (0.75 * 0.3 / 1.5 = 0.15 = 0.25 * 0.6)
    assert choose_target([0.95, 0.6], [0.9, 0.5]) == 1
    assert choose_target([0.9, 0.3], [0.9, 0.6]) == 0      # tie goes to the first
    assert choose_target([0.9, 0.31], [0.9, 0.6]) == 1


def test_objects_without_depth_or_too_far_are_left_out():
    assert choose_target([0.9, 0.99, 0.5], [np.nan, 1.6, 1.4]) == 2
    assert choose_target([0.9], [1.5]) is None
    assert choose_target([], []) is None
    with pytest.raises(ValueError, match="z_max"):
        priority_scores([0.5], [1.0], z_max=0.0)


def test_centroid_depth():
    assert centroid_depth(np.array([[0.0, 0.0, 0.8], [0.1, 0.0, 1.0]])) == pytest.approx(0.9)
    assert np.isnan(centroid_depth(np.zeros((0, 3))))
