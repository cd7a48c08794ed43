"""Fruit perception on exactly rendered spheres (fruitkit.SphereCamera): barycentres from
the colour-masked depth by the MLESAC fit, against the true centres, with occlusion and
depth holes; the thesis's priority choice; DemoV1's click."""

from __future__ import annotations

import numpy as np
import pytest
from fruitkit import SphereCamera, fruit_at, ur5e_robot

from mmexec.skills.fruit.perception import (
    PerceptionSettings,
    click_estimate,
    estimate_fruit,
    merge_estimates,
)
from mmexec.skills.perception.detector import ColourBlobDetector
from mmexec.skills.perception.priority import choose_target, priority_scores

SETTINGS = PerceptionSettings(max_depth=1.5, radius_range=(0.025, 0.055), min_confidence=0.5, min_height=0.3)


def _frame(spheres, **kw):
    robot = ur5e_robot(spheres)
    robot.camera = SphereCamera(robot, spheres, **kw)
    f = robot.camera.frame()
    robot.close()
    return f


def _nearest(est, truth):
    return min(truth, key=lambda t: np.linalg.norm(est.centre - t[1]))


def test_every_fruit_found_with_its_class_and_a_centre_within_3_mm():
    spheres = [("apple", fruit_at(0.95, 0.10, 0.85), 0.035), ("yellow_ball", fruit_at(1.05, -0.15, 0.70), 0.04),
               ("blue_ball", fruit_at(0.90, -0.02, 0.60), 0.03)]
    f = _frame(spheres)
    found = estimate_fruit(f, ColourBlobDetector(), SETTINGS, np.random.default_rng(0))
    assert sorted(e.label for e in found) == sorted(s[0] for s in spheres)
    for e in found:
        label, c, r = _nearest(e, spheres)
        assert e.label == label
        assert np.linalg.norm(e.centre - c) < 0.003, (label, e.centre, c)
        assert e.radius == pytest.approx(r, abs=0.003)
        # z: the depth of the visible points' centroid, a little nearer than the centre
        assert c[0] - 0.3 - r < e.z < c[0] - 0.3
        assert e.score == pytest.approx(float(priority_scores([e.confidence], [e.z])[0]))


def test_a_partly_hidden_fruit_and_depth_holes_still_fit_within_5_mm():
    # a grey box (no colour) in front of a sixth of the apple: a leaf
    c = fruit_at(0.9, 0.0, 0.8)
    spheres = [("apple", c, 0.04)]
    f = _frame(spheres, holes=0.1)
    K = f.intrinsics
    r_px = 0.04 * K.fx / 0.6
    u0 = int(K.cx - 0.6 * r_px)
    f.rgb[:, :u0] = 128  # the image's left, a sixth of the disc
    f.depth[:, :u0] = 0.5
    found = estimate_fruit(f, ColourBlobDetector(), SETTINGS, np.random.default_rng(1))
    assert len(found) == 1
    assert np.linalg.norm(found[0].centre - c) < 0.005
    assert found[0].confidence < 0.75  # a cut disc scores lower than a whole one


def test_the_nearest_of_equally_confident_fruit_is_chosen():
    spheres = [("apple", fruit_at(1.2, 0.15, 0.8), 0.035), ("apple", fruit_at(0.8, -0.15, 0.8), 0.035)]
    found = estimate_fruit(_frame(spheres), ColourBlobDetector(), SETTINGS, np.random.default_rng(0))
    k = choose_target([e.confidence for e in found], [e.z for e in found])
    assert k is not None and found[k].centre[0] == pytest.approx(0.8, abs=0.005)


def test_fruit_on_the_floor_and_beyond_z_max_are_ignored():
    spheres = [("apple", fruit_at(0.9, 0.0, 0.035), 0.035), ("green_ball", fruit_at(2.2, 0.0, 0.8), 0.04)]
    assert estimate_fruit(_frame(spheres), ColourBlobDetector(), SETTINGS, np.random.default_rng(0)) == []


def test_merge_keeps_one_estimate_per_fruit_the_best_fitted():
    spheres = [("apple", fruit_at(0.95, 0.10, 0.85), 0.035)]
    f = _frame(spheres)
    a = estimate_fruit(f, ColourBlobDetector(), SETTINGS, np.random.default_rng(0))
    b = estimate_fruit(f, ColourBlobDetector(), SETTINGS, np.random.default_rng(5))
    merged = merge_estimates([a, b], 0.03)
    assert len(merged) == 1 and merged[0].points == max(a[0].points, b[0].points)


@pytest.mark.parametrize("offset_px", [0, 8])
def test_a_click_on_the_fruit_gives_its_barycentre(offset_px):
    c = fruit_at(0.9, 0.05, 0.75)
    f = _frame([("apple", c, 0.035)])
    T = np.linalg.inv(f.T_map_base @ f.T_base_camera)
    pc = (T @ np.append(c, 1.0))[:3]
    uv = (f.intrinsics.matrix() @ pc)[:2] / pc[2]
    centre, radius, how = click_estimate(f, (uv[0] + offset_px, uv[1]), SETTINGS, np.random.default_rng(0))
    assert np.linalg.norm(centre - c) < 0.005, how
    assert radius == pytest.approx(0.035, abs=0.004)


def test_a_click_on_the_fruit_without_a_fit_goes_along_the_ray():
    c = fruit_at(0.9, 0.0, 0.75)
    f = _frame([("apple", c, 0.035)])
    T = np.linalg.inv(f.T_map_base @ f.T_base_camera)
    pc = (T @ np.append(c, 1.0))[:3]
    uv = (f.intrinsics.matrix() @ pc)[:2] / pc[2]
    narrow = PerceptionSettings(radius_range=(0.05, 0.055))  # no sphere of the apple's size fits
    centre, radius, how = click_estimate(f, (uv[0], uv[1]), narrow, np.random.default_rng(0))
    assert how == "ray" and radius == pytest.approx(0.0525)
    # the surface point at the centre pixel plus the radius along the ray: 1.75 cm beyond the true centre
    assert np.linalg.norm(centre - c) == pytest.approx(0.0525 - 0.035, abs=0.002)
