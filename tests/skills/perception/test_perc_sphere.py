from __future__ import annotations

import numpy as np
import pytest

from mmexec.drivers.interfaces import CameraIntrinsics
from mmexec.skills.perception.sphere import (
    SphereFitConfig,
    depth_to_points,
    fit_sphere,
    refine_sphere,
    render_sphere_depth,
    render_sphere_view,
    spheres_from_samples,
)

K = CameraIntrinsics.from_fov(640, 480, 0.994837)
CFG = SphereFitConfig(radius_range=(0.03, 0.05))


def _on_sphere(rng, n, centre, radius, cap=1.0):
    """n points on a sphere, within the cap facing -z (towards a camera at the origin)."""
    d = rng.normal(size=(n * 4, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d[d[:, 2] < -(1.0 - 2.0 * cap)][:n]
    return centre + radius * d


def test_four_point_spheres_exact_and_degenerate():
    rng = np.random.default_rng(0)
    c, r = np.array([0.1, -0.2, 0.8]), 0.04
    good = _on_sphere(rng, 4, c, r)
    flat = np.array([[0, 0, 1.0], [0.1, 0, 1.0], [0, 0.1, 1.0], [0.1, 0.1, 1.0]])
    repeated = np.array([good[0], good[0], good[1], good[2]])
    centres, radii, ok = spheres_from_samples(np.stack([good, flat, repeated]))
    assert ok.tolist() == [True, False, False]
    np.testing.assert_allclose(centres[0], c, atol=1e-9)
    assert radii[0] == pytest.approx(r, abs=1e-9)
    assert np.all(np.isnan(centres[1:]))


def test_depth_to_points_backprojects_box_mask_and_range():
    depth = np.full((480, 640), 0.8, np.float32)
    depth[100, 200] = np.nan
    depth[101, 200] = 2.0          # beyond max_depth
    mask = np.zeros((480, 640), bool)
    mask[100:102, 200:202] = True
    pts = depth_to_points(depth, K, mask=mask, box=(190, 90, 20, 20), max_depth=1.5)
    assert pts.shape == (2, 3)     # the nan and the far pixel are gone
    u, v = 201, 100
    expected = [(u - K.cx) / K.fx * 0.8, (v - K.cy) / K.fy * 0.8, 0.8]
    np.testing.assert_allclose(pts[0], expected, atol=1e-6)
    assert depth_to_points(depth, K, box=(0, 0, 640, 480)).shape == (640 * 480 - 2, 3)
    with pytest.raises(ValueError, match="mask shape"):
        depth_to_points(depth, K, mask=mask[:10])


def test_rendered_depth_is_on_the_sphere():
    c, r = np.array([0.05, 0.02, 0.7]), 0.04
    pts = depth_to_points(render_sphere_depth(K, c, r), K)
    assert len(pts) > 1000
    np.testing.assert_allclose(np.linalg.norm(pts - c, axis=1), r, atol=1e-6)
    assert np.all(np.einsum("ij,ij->i", pts - c, pts) <= 1e-9)  # only the side facing the camera


def test_exact_full_view_recovers_centre_and_radius():
    c, r = np.array([-0.1, 0.05, 0.9]), 0.042
    pts = depth_to_points(render_sphere_depth(K, c, r), K)
    fit = fit_sphere(pts, CFG, np.random.default_rng(1))
    assert fit is not None
    np.testing.assert_allclose(fit.centre, c, atol=1e-5)
    assert fit.radius == pytest.approx(r, abs=1e-5)
    assert fit.inlier_fraction == 1.0 and not fit.radius_clamped


@pytest.mark.parametrize("visible,dist", [(0.2, 1.0), (0.4, 0.75), (0.6, 0.5)])
def test_partial_view_with_holes_and_outliers(visible, dist):
    rng = np.random.default_rng(int(visible * 10))
    c, r = np.array([0.08, -0.04, dist]), 0.04
    view = render_sphere_view(K, c, r, rng, visible=visible, holes=0.10, outliers=0.05)
    pts = depth_to_points(view.depth, K, mask=view.mask)
    fit = fit_sphere(pts, CFG, rng)
    assert fit is not None
    # the p95 bound; a 20 % cap at 1 m fixes the radius (and so the centre along
    # the ray) least well: 5 mm here, under 1 mm at 0.5 m
    assert np.linalg.norm(fit.centre - c) < 0.008
    assert fit.radius == pytest.approx(r, abs=0.008)
    # the outliers (5 % of the visible pixels) are not inliers; most of the rest are
    assert 0.80 < fit.inlier_fraction < 0.97
    # the naive centroid the fit replaces is off by a good part of the radius
    assert np.linalg.norm(pts.mean(axis=0) - c) > 0.015


def test_deterministic_for_a_seed():
    view = render_sphere_view(K, np.array([0.0, 0.0, 0.8]), 0.04, np.random.default_rng(5), visible=0.3)
    pts = depth_to_points(view.depth, K, mask=view.mask)
    a = fit_sphere(pts, CFG, np.random.default_rng(9))
    b = fit_sphere(pts, CFG, np.random.default_rng(9))
    assert a is not None and b is not None
    np.testing.assert_array_equal(a.centre, b.centre)


def test_larger_neighbour_in_the_mask_is_rejected():
    """Two touching balls of one colour in one mask: the fit takes the one with more
    points and leaves the other's out."""
    rng = np.random.default_rng(3)
    a = _on_sphere(rng, 800, np.array([0.0, 0.0, 0.8]), 0.04, cap=0.4)
    b = _on_sphere(rng, 400, np.array([0.085, 0.0, 0.8]), 0.045, cap=0.4)
    fit = fit_sphere(np.vstack([a, b]), CFG, rng)
    assert fit is not None
    assert np.linalg.norm(fit.centre - [0.0, 0.0, 0.8]) < 1e-3
    # b's points near where the balls touch lie within epsilon of a's surface too
    assert fit.inliers[:800].all() and fit.inliers[800:].mean() < 0.05


def test_flat_patch_and_wrong_size_are_no_fit():
    rng = np.random.default_rng(4)
    wall = np.column_stack([rng.uniform(-0.05, 0.05, (500, 2)), 0.8 + rng.normal(0, 0.001, 500)])
    assert fit_sphere(wall, CFG, rng) is None
    big = _on_sphere(rng, 500, np.array([0.0, 0.0, 1.0]), 0.10, cap=0.4)
    assert fit_sphere(big, CFG, rng) is None
    assert fit_sphere(big[:5], CFG, rng) is None   # fewer than min_points


def test_refinement_clamps_radius_to_the_range():
    rng = np.random.default_rng(6)
    c = np.array([0.0, 0.0, 0.8])
    pts = _on_sphere(rng, 300, c, 0.055, cap=0.3)
    centre, radius, clamped = refine_sphere(pts, c + [0.0, 0.0, -0.01], 0.05, (0.03, 0.05))
    assert clamped and radius == 0.05
    # with the radius held 5 mm short, the centre moves towards the points by about that
    assert np.linalg.norm(centre - c) < 0.008


def test_config_validation():
    assert SphereFitConfig().validate() == []
    errs = SphereFitConfig(radius_range=(0.05, 0.03), min_points=3, noise_sigma=0.0).validate()
    assert len(errs) == 3
    with pytest.raises(ValueError, match="radius_range"):
        fit_sphere(np.zeros((50, 3)), SphereFitConfig(radius_range=(0.0, 0.1)), np.random.default_rng(0))


def test_algorithm_1_2_from_a_detection():
    """RGB-D view of a red ball in front of a grey wall: the colour detector's box and
    the class' colour mask select the points, the fit finds the centre."""
    from mmexec.skills.perception.detector import ColourBlobDetector, colour_mask

    rng = np.random.default_rng(8)
    c, r = np.array([0.12, 0.05, 0.7]), 0.04
    ball = render_sphere_depth(K, c, r)
    on = np.isfinite(ball)
    depth = np.full(ball.shape, 1.2, np.float32)   # the wall behind
    depth[on] = ball[on] + rng.normal(0, 0.0014, int(on.sum()))
    # shade the ball by its normal's component towards the camera
    pts = depth_to_points(ball, K)
    shade = np.clip(-np.einsum("ij,ij->i", (pts - c) / r, pts / np.linalg.norm(pts, axis=1)[:, None]), 0, 1)
    rgb = rng.integers(100, 140, (*ball.shape, 3)).astype(np.uint8)
    rgb[on] = (np.outer(0.3 + 0.7 * shade, [200, 25, 30])).astype(np.uint8)
    det = ColourBlobDetector()
    (found,) = det.detect(rgb)
    assert found.label == "apple"
    mask = colour_mask(rgb, det.colours["apple"], found.box)
    fit = fit_sphere(depth_to_points(depth, K, mask=mask, box=found.box), CFG, rng)
    assert fit is not None and np.linalg.norm(fit.centre - c) < 0.002
