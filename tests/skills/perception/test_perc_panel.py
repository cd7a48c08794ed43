from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from mmexec.drivers.geometry import rigid_fit
from mmexec.skills.perception.averaging import rotation_angle
from mmexec.skills.perception.panel import (
    Button,
    PanelFitConfig,
    PanelFitError,
    PanelLayout,
    PressConfig,
    button_poses,
    fit_panel,
    press_path,
    press_paths,
)

# the thesis' box: 7 markers around 3 buttons of different sizes (panel frame, m)
LAYOUT = PanelLayout(
    markers={
        0: (-0.18, 0.12, 0.0), 1: (0.0, 0.13, 0.0), 2: (0.18, 0.12, 0.0),
        3: (-0.19, -0.01, 0.0), 4: (0.19, 0.0, 0.0),
        5: (-0.17, -0.12, 0.0), 6: (0.17, -0.12, 0.0),
    },
    buttons=(
        Button("red", (-0.09, 0.0, 0.025), 0.004),
        Button("green", (0.0, -0.02, 0.02), 0.003),
        Button("black", (0.09, 0.01, 0.03), 0.005),
    ),
)


def _pose(rvec, t):
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, dtype=float))[0]
    T[:3, 3] = t
    return T


# the panel 0.6 m in front of the arm base, face towards the robot, tilted
T_TRUE = _pose([1.3, -1.0, 1.1], [0.6, 0.05, 0.35])


def _seen(T, ids=None, noise=0.0, rng=None):
    out = {}
    for i, p in LAYOUT.markers.items():
        if ids is None or i in ids:
            c = T[:3, :3] @ np.asarray(p) + T[:3, 3]
            out[i] = c + (rng.normal(0, noise, 3) if noise else 0.0)
    return out


def _pose_error(T, T_ref):
    return np.linalg.norm(T[:3, 3] - T_ref[:3, 3]), math.degrees(rotation_angle(T[:3, :3], T_ref[:3, :3]))


def test_rigid_fit_exact_and_proper_rotation():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(6, 3))
    R, t = rigid_fit(src, src @ T_TRUE[:3, :3].T + T_TRUE[:3, 3])
    np.testing.assert_allclose(R, T_TRUE[:3, :3], atol=1e-12)
    np.testing.assert_allclose(t, T_TRUE[:3, 3], atol=1e-12)
    # a mirrored point set still gives a rotation (det +1), never a reflection
    R, _ = rigid_fit(src, src * [1, 1, -1])
    assert np.linalg.det(R) == pytest.approx(1.0)
    # planar too
    a = 0.7
    R2 = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    R, t = rigid_fit(src[:, :2], src[:, :2] @ R2.T + [0.1, -0.2])
    np.testing.assert_allclose(R, R2, atol=1e-12)
    np.testing.assert_allclose(t, [0.1, -0.2], atol=1e-12)


def test_exact_layout():
    fit = fit_panel(LAYOUT, _seen(T_TRUE))
    dp, da = _pose_error(fit.T_frame_panel, T_TRUE)
    assert dp < 1e-9 and da < 1e-6
    assert fit.inliers == tuple(range(7)) and fit.rejected == ()
    np.testing.assert_allclose(fit.normal, T_TRUE[:3, 2], atol=1e-9)


@pytest.mark.parametrize("wrong", [0, 3, 6])
def test_one_wrong_marker_is_rejected(wrong):
    rng = np.random.default_rng(wrong)
    seen = _seen(T_TRUE, noise=0.001, rng=rng)
    seen[wrong] = seen[wrong] + T_TRUE[:3, 2] * 0.05   # e.g. a flipped PnP solution's depth
    fit = fit_panel(LAYOUT, seen)
    assert fit.rejected == (wrong,)
    dp, da = _pose_error(fit.T_frame_panel, T_TRUE)
    assert dp < 0.002 and da < 1.0
    assert fit.residuals[wrong] > 0.04


def test_misread_id_is_rejected_with_four_markers():
    seen = _seen(T_TRUE, ids={0, 2, 5, 6})
    seen[5] = _seen(T_TRUE, ids={3})[3]   # marker 3 decoded as 5
    fit = fit_panel(LAYOUT, seen)
    assert fit.rejected == (5,) and fit.inliers == (0, 2, 6)
    assert _pose_error(fit.T_frame_panel, T_TRUE)[0] < 1e-9


def test_three_markers_only():
    fit = fit_panel(LAYOUT, _seen(T_TRUE, ids={1, 3, 6}))
    assert fit.inliers == (1, 3, 6)
    dp, da = _pose_error(fit.T_frame_panel, T_TRUE)
    assert dp < 1e-9 and da < 1e-6
    # a wrong one of three cannot be out-voted, but the residual refuses the fit
    seen = _seen(T_TRUE, ids={1, 3, 6})
    seen[3] = seen[3] + 0.05
    with pytest.raises(PanelFitError, match="RMS"):
        fit_panel(LAYOUT, seen)


def test_too_few_or_collinear_markers():
    with pytest.raises(PanelFitError, match="2 of its markers seen"):
        fit_panel(LAYOUT, {**_seen(T_TRUE, ids={0, 2}), 99: np.zeros(3)})
    line = PanelLayout({0: (0.0, 0.0, 0.0), 1: (0.1, 0.0, 0.0), 2: (0.2, 0.0, 0.0), 3: (0.0, 0.2, 0.0)}, ())
    pts = {i: np.asarray(p) for i, p in line.markers.items() if i != 3}
    with pytest.raises(PanelFitError, match="collinear"):
        fit_panel(line, pts)
    assert any("one line" in e for e in PanelLayout({i: line.markers[i] for i in (0, 1, 2)}, ()).validate())
    assert LAYOUT.validate() == []


def test_button_poses_follow_the_panel():
    fit = fit_panel(LAYOUT, _seen(T_TRUE))
    poses = button_poses(fit.T_frame_panel, LAYOUT)
    for b in LAYOUT.buttons:
        np.testing.assert_allclose(poses[b.name][:3, 3], T_TRUE[:3, :3] @ b.position + T_TRUE[:3, 3], atol=1e-9)
        np.testing.assert_allclose(poses[b.name][:3, :3], T_TRUE[:3, :3], atol=1e-9)


@pytest.mark.parametrize("approach_axis", [0, 2])
def test_press_path_is_straight_and_orthogonal(approach_axis):
    T_button = button_poses(T_TRUE, LAYOUT)["black"]
    cfg = PressConfig(standoff=0.08, overtravel=0.003, step=0.01)
    path = press_path(T_button, approach_axis, travel=0.005, name="black", config=cfg)
    n, cap = T_button[:3, 2], T_button[:3, 3]
    p = path.press[:, :3, 3]
    # every waypoint on the normal through the cap centre, evenly spaced, from the standoff
    # above it to travel + overtravel below it
    np.testing.assert_allclose(np.cross(p - cap, n), 0.0, atol=1e-12)
    heights = (p - cap) @ n
    assert heights[0] == pytest.approx(0.08) and heights[-1] == pytest.approx(-0.008)
    steps = np.diff(heights)
    assert np.all(steps < 0) and np.all(-steps <= 0.01 + 1e-12)
    np.testing.assert_allclose(steps, steps[0])
    # the approach axis points into the face at every waypoint; the orientation is constant
    np.testing.assert_allclose(path.press[:, :3, approach_axis], np.tile(-n, (len(p), 1)), atol=1e-12)
    np.testing.assert_allclose(path.press[:, :3, :3], np.broadcast_to(path.above[:3, :3], (len(p), 3, 3)))
    np.testing.assert_allclose(path.above, path.press[0])
    assert path.depth == pytest.approx(0.008)
    np.testing.assert_allclose(path.release, path.press[::-1])
    np.testing.assert_allclose(path.release[-1], path.above)
    np.testing.assert_allclose(path.pressed[:3, 3], cap - 0.008 * n)


def test_press_paths_in_order_and_errors():
    fit = fit_panel(LAYOUT, _seen(T_TRUE))
    paths = press_paths(fit, LAYOUT, 0, order=["green", "red"])
    assert [pp.button for pp in paths] == ["green", "red"]
    assert len(press_paths(fit, LAYOUT, 2)) == 3
    with pytest.raises(KeyError, match="known: red, green, black"):
        press_paths(fit, LAYOUT, 0, order=["blue"])
    with pytest.raises(ValueError, match="standoff"):
        press_path(np.eye(4), 0, travel=0.0, config=PressConfig(standoff=0.0))
    with pytest.raises(ValueError, match="approach_axis"):
        press_path(np.eye(4), 1, travel=0.0)


def test_config_tightens_inlier_distance():
    rng = np.random.default_rng(1)
    seen = _seen(T_TRUE, noise=0.001, rng=rng)
    seen[4] = seen[4] + np.array([0.0, 0.006, 0.0])
    assert fit_panel(LAYOUT, seen).rejected == ()
    assert fit_panel(LAYOUT, seen, PanelFitConfig(inlier_distance=0.004)).rejected == (4,)
