from __future__ import annotations

import math

import numpy as np
import pytest
from mmexec.drivers.interfaces import CameraFrame, CameraIntrinsics
from mmexec.skills.perception.averaging import rotation_angle
from mmexec.skills.perception.markers import (
    DetectorConfig,
    MarkerDetector,
    estimate_marker_pose,
    observe_markers,
    refine_pose_with_depth,
)
from mmexec.skills.perception.synthetic import look_at_marker, render_marker_view

K = CameraIntrinsics(640, 480, 615.0, 615.0, 319.5, 239.5)
L = 0.10


def _err(T_est, T_true):
    return np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]), math.degrees(rotation_angle(T_est[:3, :3], T_true[:3, :3]))


@pytest.mark.parametrize("yaw,pitch,roll,offset", [
    (0.4, 0.15, 0.3, (0.10, -0.05)),
    (-0.5, -0.2, 2.0, (-0.15, 0.10)),
    (0.6, 0.0, -1.2, (0.0, 0.0)),
])
def test_pose_accuracy_at_one_metre_with_noise(yaw, pitch, roll, offset):
    rng = np.random.default_rng(11)
    T_true = look_at_marker(1.0, yaw=yaw, pitch=pitch, roll=roll, offset=offset)
    view = render_marker_view(K, T_true, 7, L, noise_sigma=3.0, rng=rng)
    det = MarkerDetector(DetectorConfig(marker_length=L))
    found = det.detect(view.rgb)
    assert [d.id for d in found] == [7]
    assert np.abs(found[0].corners - view.corners).max() < 0.5
    T, reproj = estimate_marker_pose(found[0].corners, K, L)
    dp, da = _err(T, T_true)
    assert dp < 0.01 and da < 2.0, (dp, da)
    assert reproj < 0.5


def test_roi_tracking_and_downscale_paths_agree():
    T_true = look_at_marker(1.0, yaw=0.3, pitch=0.1)
    view = render_marker_view(K, T_true, 3, L, noise_sigma=2.0)
    det = MarkerDetector(DetectorConfig(marker_length=L))
    first = det.detect(view.rgb)
    assert det.last_method == "downscaled"
    second = det.detect(view.rgb)
    assert det.last_method == "roi"
    assert np.allclose(first[0].corners, second[0].corners, atol=0.05)
    # marker gone: the ROI misses, and so does every fallback
    blank = np.full_like(view.rgb, 128)
    assert det.detect(blank) == [] and det.last_method == "none"


def test_small_far_marker_uses_full_resolution_fallback():
    T_true = look_at_marker(2.0, yaw=0.2)
    view = render_marker_view(K, T_true, 9, 0.06, noise_sigma=1.0)
    det = MarkerDetector(DetectorConfig(marker_length=0.06, min_marker_perimeter_px=20))
    found = det.detect(view.rgb)
    assert [d.id for d in found] == [9]
    assert det.last_method == "full"


def test_depth_refinement_fixes_wrong_scale():
    T_true = look_at_marker(1.2, yaw=0.3, pitch=0.1, offset=(0.05, 0.02))
    view = render_marker_view(K, T_true, 5, L, noise_sigma=2.0, depth_noise_sigma=0.003)
    det = MarkerDetector(DetectorConfig(marker_length=L))
    found = det.detect(view.rgb)
    # a marker length 8 % off (a misprint) scales the translation by 8 %
    T_wrong, _ = estimate_marker_pose(found[0].corners, K, L * 1.08)
    assert _err(T_wrong, T_true)[0] > 0.08
    T_ref, ok = refine_pose_with_depth(T_wrong, found[0].corners, view.depth)
    assert ok
    dp, da = _err(T_ref, T_true)
    assert dp < 0.01 and da < 2.0
    # no usable depth: unchanged and flagged
    T_same, ok = refine_pose_with_depth(T_wrong, found[0].corners, np.full_like(view.depth, np.nan))
    assert not ok and np.array_equal(T_same, T_wrong)


def test_observe_markers_in_map_frame():
    T_cam_marker = look_at_marker(1.0, yaw=-0.3, pitch=0.1)
    view = render_marker_view(K, T_cam_marker, 4, L, noise_sigma=2.0)
    # camera 0.5 m up on the base, looking along base +x (optical z = base x)
    T_base_cam = np.array([[0, 0, 1, 0.1], [-1, 0, 0, 0.0], [0, -1, 0, 0.5], [0, 0, 0, 1]], dtype=float)
    c, s = math.cos(0.7), math.sin(0.7)
    T_map_base = np.array([[c, -s, 0, 2.0], [s, c, 0, -1.0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)
    frame = CameraFrame(view.rgb, view.depth, K, 12.5, T_base_cam, T_map_base)
    obs = observe_markers(frame, MarkerDetector(DetectorConfig(marker_length=L)))
    assert len(obs) == 1
    o = obs[0]
    assert o.id == 4 and o.stamp == 12.5 and o.depth_refined
    truth = T_map_base @ T_base_cam @ T_cam_marker
    dp, da = _err(o.T_map_marker, truth)
    assert dp < 0.01 and da < 2.0
    assert o.distance == pytest.approx(1.0, abs=0.01)
    # the marker faces the camera: its z axis points back towards the base in map
    to_base = T_map_base[:3, 3] - o.T_map_marker[:3, 3]
    assert np.dot(o.T_map_marker[:3, 2], to_base) > 0
    assert observe_markers(frame, MarkerDetector(DetectorConfig(marker_length=L)), ids={99}) == []


def test_bad_config_rejected():
    with pytest.raises(ValueError, match="unknown ArUco dictionary"):
        MarkerDetector(DetectorConfig(dictionary="DICT_4X4_51"))
    with pytest.raises(ValueError, match="threshold_window"):
        MarkerDetector(DetectorConfig(threshold_window=8))
