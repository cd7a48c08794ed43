"""Grasp point from a box and depth (paper III-C), the top-down and front grasp frames,
and the dangerous-object pixel correction (IV-E), on analytically rendered scenes."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from mmexec.drivers.interfaces import CameraFrame, CameraIntrinsics, Pose2D
from mmexec.skills.manipulation.grasp import grasp_poses
from mmexec.skills.perception.grasp_point import (
    GraspPoint,
    GraspPointConfig,
    GraspPointError,
    back_project,
    correct_grasp_pixel,
    estimate_grasp,
    move_grasp,
    pixel_depth,
)
from mmexec.skills.perception.synthetic_objects import (
    BACKGROUND,
    SUPPORT,
    SceneObject,
    look_at,
    object_box,
    render_scene,
    spoil_depth,
)

K = CameraIntrinsics.from_fov(640, 480, 0.994837)  # the LoCoBot D435 stand-in, f = 590 px
BASE = Pose2D(1.0, 2.0, 0.5)                          # the robot somewhere in the map
BASE_SUPPORT = 0.30                                   # table top [m]


def _frame(objects: list[SceneObject], eye: tuple[float, float, float], target: tuple[float, float, float], *,
           support_z: float | None = 0.0, spoil: int | None = None) -> tuple[CameraFrame, np.ndarray]:
    """A frame of ``objects`` seen from ``eye`` (in the robot's base frame) towards
    ``target``, the base at :data:`BASE`; returns the frame and the label image."""
    T_map_base = BASE.matrix()
    world = [SceneObject(o.kind, tuple(T_map_base[:3, :3] @ o.centre + T_map_base[:3, 3]), o.size,  # type: ignore[arg-type]
                         o.yaw + BASE.theta, o.colour) for o in objects]
    T_map_cam = look_at(tuple(T_map_base[:3, :3] @ eye + T_map_base[:3, 3]),  # type: ignore[arg-type]
                        tuple(T_map_base[:3, :3] @ target + T_map_base[:3, 3]))  # type: ignore[arg-type]
    view = render_scene(world, T_map_cam, K, support_z=support_z)
    depth = view.depth if spoil is None else spoil_depth(view.depth, np.random.default_rng(spoil))
    return CameraFrame(view.rgb, depth, K, 0.0, np.linalg.inv(T_map_base) @ T_map_cam, T_map_base), view.labels


def frame_camera_position(frame: CameraFrame) -> np.ndarray:
    return (frame.T_map_base @ frame.T_base_camera)[:3, 3]


def _in_map(p: tuple[float, float, float]) -> np.ndarray:
    T = BASE.matrix()
    return T[:3, :3] @ np.asarray(p) + T[:3, 3]


def _angle_mod_pi(a: float, b: float) -> float:
    return abs(math.remainder(a - b, math.pi))


# --------------------------------------------------------------------------- the synthetic scenes


def test_rendered_depth_is_exact() -> None:
    """A box's front face 0.8 m ahead of a level camera, a cylinder beside it."""
    T = look_at((0.0, 0.0, 0.5), (1.0, 0.0, 0.5))
    objs = [SceneObject("box", (0.85, 0.0, 0.5), (0.10, 0.2, 0.2), colour=(10, 200, 10)),
            SceneObject("cylinder", (1.0, 0.4, 0.5), (0.1, 0.1, 0.2))]
    v = render_scene(objs, T, K, support_z=0.0)
    assert v.depth[240, 320] == pytest.approx(0.8, abs=1e-6) and v.labels[240, 320] == 0
    # the cylinder's nearest point along the ray through its axis: 1.0 - r along the ray
    u = K.cx + K.fx * (-0.4) / 1.0
    assert v.labels[240, round(u)] == 1
    assert v.depth[240, round(u)] == pytest.approx(1.0 - 0.05 / math.hypot(1.0, 0.4), abs=2e-3)
    assert v.labels[479, 320] == SUPPORT and v.labels[0, 320] == BACKGROUND and np.isnan(v.depth[0, 320])
    _, _, w, h = object_box(v.labels, 0)  # type: ignore[misc]
    assert w == pytest.approx(0.2 * K.fx / 0.8, abs=2) and h == pytest.approx(0.2 * K.fy / 0.8, abs=2)
    assert object_box(v.labels, 5) is None


def test_spoilt_depth_has_the_asked_holes_and_noise() -> None:
    flat = np.full((240, 320), 1.0, np.float32)
    d = spoil_depth(flat, np.random.default_rng(0), holes=0.1, flying=0.0)
    assert np.isnan(d).mean() == pytest.approx(0.1, abs=0.005)
    assert float(np.nanstd(d)) == pytest.approx(0.002, rel=0.15)


# --------------------------------------------------------------------------- depth at a pixel


def test_pixel_depth_is_the_median_of_valid_depths() -> None:
    d = np.full((20, 20), 0.8)
    d[9:12, 9:12] = [[np.nan, 0.0, 0.79], [0.81, 7.0, np.inf], [0.8, 0.8, 0.02]]
    assert pixel_depth(d, (10, 10), (1, 1), min_valid=4) == pytest.approx(0.8)


def test_pixel_depth_grows_the_window_over_a_hole_up_to_the_box() -> None:
    d = np.full((40, 40), np.nan)
    d[5:35, 5:35] = 1.2
    d[12:28, 12:28] = np.nan                                # a hole at the centre
    assert pixel_depth(d, (20, 20), (2, 2), limit=(5, 5, 34, 34)) == pytest.approx(1.2)
    with pytest.raises(GraspPointError, match=r"no valid depth around pixel \(20.0, 20.0\) within the box "
                                              r"\(14, 14, 26, 26\)"):
        pixel_depth(d, (20, 20), (2, 2), limit=(14, 14, 26, 26))


def test_back_project_is_the_pinhole_inverse() -> None:
    p = back_project((400.0, 100.0), 0.9, K)
    assert K.fx * p[0] / p[2] + K.cx == pytest.approx(400.0) and K.fy * p[1] / p[2] + K.cy == pytest.approx(100.0)
    assert p[2] == 0.9


# --------------------------------------------------------------------------- grasp point


def test_box_on_a_table_seen_from_above_exact_depth() -> None:
    box = SceneObject("box", (0.7, 0.05, 0.35), (0.10, 0.05, 0.10), yaw=0.3)
    frame, labels = _frame([box], (0.0, 0.0, 0.56), (0.7, 0.0, 0.3), support_z=BASE_SUPPORT)
    g = estimate_grasp(frame, object_box(labels, 0), size=box.size)  # type: ignore[arg-type]
    truth = _in_map(box.centre)
    assert np.linalg.norm(g.centre - truth) < 0.002
    assert g.footprint == pytest.approx((0.10, 0.05), abs=0.002) and g.height == pytest.approx(0.10, abs=0.002)
    assert _angle_mod_pi(g.yaw, box.yaw + BASE.theta) < math.radians(1.5)
    assert g.support_z == pytest.approx(0.30, abs=0.002)
    # the paper's grasp point is on the visible surface, centimetres from the centre of mass
    assert np.linalg.norm(g.surface - truth) > 0.02


def test_surface_point_is_the_box_centre_pixel_in_map() -> None:
    box = SceneObject("box", (0.7, 0.0, 0.35), (0.10, 0.05, 0.10))
    frame, labels = _frame([box], (0.0, 0.0, 0.56), (0.7, 0.0, 0.3), support_z=BASE_SUPPORT)
    b = object_box(labels, 0)
    assert b is not None
    g = estimate_grasp(frame, b)
    u, v = b[0] + (b[2] - 1) / 2, b[1] + (b[3] - 1) / 2
    assert g.pixel == (u, v)
    assert frame.depth is not None
    T = frame.T_map_base @ frame.T_base_camera
    expected = T[:3, :3] @ back_project((u, v), float(frame.depth[round(v), round(u)]), K) + T[:3, 3]
    np.testing.assert_allclose(g.surface, expected, atol=5e-4)


def _shelf(item: SceneObject) -> list[SceneObject]:
    """``item`` on a 2 cm shelf board whose top is the item's bottom."""
    z = item.centre[2] - item.size[2] / 2
    return [item, SceneObject("box", (item.centre[0] + 0.15, 0.0, z - 0.01), (0.4, 1.0, 0.02), colour=(120, 100, 80))]


def test_front_face_only_the_size_completes_the_hidden_depth() -> None:
    """From below the shelf's top the camera sees only the box's front face: the
    catalogue's size puts the centre half the box's depth behind it."""
    item = SceneObject("box", (0.7, 0.0, 0.55), (0.10, 0.05, 0.10))   # 10 cm deep along the view
    frame, labels = _frame(_shelf(item), (0.0, 0.0, 0.40), (0.7, 0.0, 0.45), support_z=None)
    b = object_box(labels, 0)
    g = estimate_grasp(frame, b, size=item.size)  # type: ignore[arg-type]
    assert np.linalg.norm(g.centre - _in_map(item.centre)) < 0.003
    assert g.footprint == pytest.approx((0.10, 0.05), abs=0.002)
    # without the size the hidden half is missing and the board's edge is taken for the object
    blind = estimate_grasp(frame, b)  # type: ignore[arg-type]
    assert np.linalg.norm(blind.centre - _in_map(item.centre)) > 0.04


def test_two_faces_seen_from_below_give_the_orientation() -> None:
    """An L of two faces has two minimum-area rectangles (one flush with the hypotenuse);
    the faces fix the right one."""
    item = SceneObject("box", (0.7, 0.0, 0.55), (0.10, 0.05, 0.10), yaw=0.7)
    frame, labels = _frame(_shelf(item), (0.0, 0.0, 0.40), (0.7, 0.0, 0.45), support_z=None)
    g = estimate_grasp(frame, object_box(labels, 0))  # type: ignore[arg-type]
    assert _angle_mod_pi(g.yaw, item.yaw + BASE.theta) < math.radians(1.5)
    assert np.linalg.norm(g.centre[:2] - _in_map(item.centre)[:2]) < 0.003


def test_a_box_cutting_the_item_is_grown_when_the_size_is_known() -> None:
    """A detector's box missing the item's top 8 %: grown by 10 % per edge, the top
    is back; with the growth off, the centre drops."""
    item = SceneObject("cylinder", (0.7, 0.0, 0.56), (0.05, 0.05, 0.12))
    frame, labels = _frame(_shelf(item), (0.0, 0.0, 0.56), (0.7, 0.0, 0.5), support_z=None)
    x, y, w, h = object_box(labels, 0)  # type: ignore[misc]
    cut = (x, y + round(0.08 * h), w, h - round(0.08 * h))
    g = estimate_grasp(frame, cut, size=item.size)
    assert np.linalg.norm(g.centre - _in_map(item.centre)) < 0.004
    as_given = estimate_grasp(frame, cut, size=item.size, config=GraspPointConfig(box_grow=0.0))
    assert as_given.centre[2] < _in_map(item.centre)[2] - 0.005


def test_cylinder_on_a_table() -> None:
    can = SceneObject("cylinder", (0.65, -0.1, 0.34), (0.06, 0.06, 0.08))
    frame, labels = _frame([can], (0.0, 0.0, 0.56), (0.7, 0.0, 0.3), support_z=BASE_SUPPORT)
    g = estimate_grasp(frame, object_box(labels, 0), size=can.size)  # type: ignore[arg-type]
    assert np.linalg.norm(g.centre - _in_map(can.centre)) < 0.004
    assert g.top_width == pytest.approx(0.06, abs=0.002)


def test_noisy_depth_with_a_hole_at_the_box_centre() -> None:
    item = SceneObject("box", (0.8, 0.0, 0.36), (0.12, 0.06, 0.12), yaw=-0.4)
    frame, labels = _frame([item], (0.0, 0.0, 0.56), (0.8, 0.0, 0.3), support_z=BASE_SUPPORT, spoil=4)
    b = object_box(labels, 0)
    assert b is not None and frame.depth is not None
    u, v = b[0] + b[2] // 2, b[1] + b[3] // 2
    frame.depth[v - 6 : v + 7, u - 6 : u + 7] = np.nan                 # the centre pixel has no depth
    g = estimate_grasp(frame, b, size=item.size)
    assert np.isfinite(g.depth) and np.linalg.norm(g.centre - _in_map(item.centre)) < 0.006


# --------------------------------------------------------------------------- grasp frames


def _rotation_ok(T: np.ndarray) -> bool:
    R = T[:3, :3]
    return bool(np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.isclose(np.linalg.det(R), 1.0))


def test_top_grasp_frame_and_poses() -> None:
    box = SceneObject("box", (0.7, 0.05, 0.35), (0.12, 0.04, 0.10), yaw=0.3)
    frame, labels = _frame([box], (0.0, 0.0, 0.56), (0.7, 0.0, 0.3), support_z=BASE_SUPPORT)
    g = estimate_grasp(frame, object_box(labels, 0), size=box.size)  # type: ignore[arg-type]
    T = g.T_map_top
    assert _rotation_ok(T) and np.allclose(T[:3, 2], [0, 0, 1]) and np.allclose(T[:3, 3], g.centre)
    long_dir = np.array([math.cos(g.yaw), math.sin(g.yaw), 0.0])
    assert abs(T[:3, 0] @ long_dir) < 1e-9                                 # fingers close across the long side
    assert T[:3, 1] @ g.view > 0                                            # tool up away from the robot
    assert g.top_width == pytest.approx(0.04, abs=0.002)
    # through the manipulation package: pre-grasp 10 cm straight above, approach pointing down
    poses = grasp_poses(T, 0, pre_grasp=(0.0, 0.0, 0.10), retract=(0.0, 0.0, 0.10))
    np.testing.assert_allclose(poses.pre_grasp[:3, 3], g.centre + [0, 0, 0.10], atol=1e-9)
    np.testing.assert_allclose(poses.grasp[:3, 3], g.centre, atol=1e-9)
    np.testing.assert_allclose(poses.pre_grasp[:3, 0], [0, 0, -1], atol=1e-9)  # WX250s tool x approaches


def test_front_grasp_frame_faces_the_camera_and_turns_for_flat_objects() -> None:
    tall = SceneObject("box", (0.7, 0.0, 0.55), (0.05, 0.05, 0.15))
    flat = SceneObject("box", (0.7, 0.0, 0.52), (0.06, 0.16, 0.04))
    for item, vertical in ((tall, False), (flat, True)):
        frame, labels = _frame(_shelf(item), (0.0, 0.0, 0.40), (0.7, 0.0, 0.45), support_z=None)
        g = estimate_grasp(frame, object_box(labels, 0), size=item.size)  # type: ignore[arg-type]
        T = g.T_map_front
        assert _rotation_ok(T) and np.allclose(T[:3, 2], -g.view)         # z horizontal, towards the camera
        assert abs(T[2, 0]) == pytest.approx(1.0 if vertical else 0.0, abs=1e-9)  # finger travel
        assert g.front_width == pytest.approx(0.04 if vertical else 0.05, abs=0.003)
        poses = grasp_poses(T, 2, pre_grasp=(0.0, 0.0, 0.10))
        cam = frame_camera_position(frame)
        assert np.linalg.norm(poses.pre_grasp[:2, 3] - cam[:2]) < np.linalg.norm(g.centre[:2] - cam[:2])


# --------------------------------------------------------------------------- errors


def test_errors_are_clear() -> None:
    box = SceneObject("box", (0.7, 0.0, 0.35), (0.10, 0.05, 0.10))
    frame, labels = _frame([box], (0.0, 0.0, 0.56), (0.7, 0.0, 0.3), support_z=BASE_SUPPORT)
    b = object_box(labels, 0)
    assert b is not None
    rgb_only = CameraFrame(frame.rgb, None, K, 0.0, frame.T_base_camera, frame.T_map_base)
    with pytest.raises(GraspPointError, match="the camera frame has no depth image"):
        estimate_grasp(rgb_only, b)
    with pytest.raises(GraspPointError, match=r"box \(700, 10, 20, 20\) is empty or outside the 640x480 image"):
        estimate_grasp(frame, (700, 10, 20, 20))
    with pytest.raises(GraspPointError, match=r"only \d+ valid depth points in the box .* \(need 30\)"):
        estimate_grasp(frame, (b[0] + 10, b[1] + 10, 4, 4))
    with pytest.raises(ValueError, match=r"GraspPointConfig: centre_window: must be in \(0, 1\], got 0"):
        estimate_grasp(frame, b, config=GraspPointConfig(centre_window=0))


# --------------------------------------------------------------------------- dangerous objects


def test_correction_is_the_mean_pixel_logged_with_both(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO, logger="mmexec.skills.perception.grasp_point"):
        c = correct_grasp_pixel((320.0, 240.0), (400.0, 200.0), (640, 480))
    assert c.corrected == (360.0, 220.0) and c.predicted == (320.0, 240.0) and c.clicked == (400.0, 200.0)
    assert "(320.0, 240.0)" in caplog.text and "(400.0, 200.0)" in caplog.text and "(360.0, 220.0)" in caplog.text
    with pytest.raises(ValueError, match=r"clicked pixel \(700, 10\) is outside the 640x480 image"):
        correct_grasp_pixel((320.0, 240.0), (700, 10), (640, 480))
    with pytest.raises(ValueError, match="clicked pixel"):
        correct_grasp_pixel((320.0, 240.0), (math.nan, 10.0), (640, 480))


def test_move_grasp_along_a_long_item_to_the_corrected_pixel() -> None:
    """A screwdriver-like bar lying across the view: the operator clicks near one end;
    the grasp moves half way there along the bar, at the same height."""
    bar = SceneObject("box", (0.6, 0.0, 0.315), (0.03, 0.20, 0.03))     # long side across the view
    frame, labels = _frame([bar], (0.0, 0.0, 0.56), (0.6, 0.0, 0.3), support_z=BASE_SUPPORT)
    b = object_box(labels, 0)
    assert b is not None
    g = estimate_grasp(frame, b, size=bar.size)
    click = (b[0] + 5.0, g.pixel[1])                                     # near the bar's left end (+y)
    c = correct_grasp_pixel(g.pixel, click, (640, 480))
    moved = move_grasp(g, frame, c.corrected, b)
    shift = moved.centre - g.centre
    along = np.array([math.cos(g.yaw), math.sin(g.yaw), 0.0])
    assert abs(shift @ along) == pytest.approx(0.045, abs=0.01)          # about a quarter of the bar
    assert abs(shift[2]) < 0.003 and moved.pixel == c.corrected
    np.testing.assert_allclose(moved.T_map_top[:3, :3], g.T_map_top[:3, :3])
    assert isinstance(moved, GraspPoint) and np.allclose(moved.T_map_top[:3, 3], moved.centre)
