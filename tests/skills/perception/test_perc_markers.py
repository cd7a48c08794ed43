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
from mmexec.skills.perception.synthetic import (
    look_at_marker,
    render_marker_view,
    render_markers_view,
)

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
    second = det.detect(view.rgb, want={3})
    assert det.last_method == "roi"
    assert np.allclose(first[0].corners, second[0].corners, atol=0.05)
    # without wanted ids the whole image is searched every frame by default
    third = det.detect(view.rgb)
    assert det.last_method == "downscaled" and np.allclose(third[0].corners, first[0].corners, atol=0.05)
    # marker gone: the ROI misses, and so does every fallback
    blank = np.full_like(view.rgb, 128)
    assert det.detect(blank, want={3}) == [] and det.last_method == "none"


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


# --------------------------------------------------------------------------- view changes


def _two_marker_views():
    """Frame 1: marker 3 alone; frame 2 (the camera turned a little): marker 3 still in
    view near where it was, and marker 8 newly in view on the other side."""
    T3 = look_at_marker(1.0, yaw=0.2, offset=(-0.20, 0.0))
    T8 = look_at_marker(1.1, yaw=-0.2, offset=(0.25, 0.02))
    only3 = render_markers_view(K, [(T3, 3)], L, noise_sigma=2.0)
    T3b = T3.copy()
    T3b[0, 3] += 0.01  # moved by about 6 px
    both = render_markers_view(K, [(T3b, 3), (T8, 8)], L, noise_sigma=2.0)
    return only3, both


def test_marker_newly_in_view_is_found_although_the_roi_hits():
    """Regression: an ROI hit used to skip the whole-image pass, so a marker that came
    into view after the camera moved was missed until the tracked one was lost."""
    only3, both = _two_marker_views()
    det = MarkerDetector(DetectorConfig(marker_length=L))
    assert [d.id for d in det.detect(only3.rgb)] == [3]
    # all markers wanted (no ids): the new one is found in the first frame showing it
    assert sorted(d.id for d in det.detect(both.rgb)) == [3, 8]
    # the wanted id is not in the ROI: the whole image is searched as well
    det2 = MarkerDetector(DetectorConfig(marker_length=L))
    det2.detect(only3.rgb)
    assert 8 in {d.id for d in det2.detect(both.rgb, want={8})}
    assert "downscaled" in det2.last_method
    # the wanted id is in the ROI: the cheap pass is enough (and the new one is not looked for)
    det3 = MarkerDetector(DetectorConfig(marker_length=L))
    det3.detect(only3.rgb)
    assert [d.id for d in det3.detect(both.rgb, want={3})] == [3] and det3.last_method == "roi"


def test_full_every_bounds_the_latency_of_a_new_marker():
    only3, both = _two_marker_views()
    det = MarkerDetector(DetectorConfig(marker_length=L, full_every=3))
    det.detect(only3.rgb)                       # whole image (nothing tracked yet)
    seen = [sorted(d.id for d in det.detect(both.rgb)) for _ in range(3)]
    assert seen == [[3], [3], [3, 8]]           # ROI, ROI, then the due whole-image pass
    with pytest.raises(ValueError, match="full_every"):
        MarkerDetector(DetectorConfig(full_every=0))


def test_observe_markers_passes_ids_as_wanted():
    only3, both = _two_marker_views()
    det = MarkerDetector(DetectorConfig(marker_length=L))
    frame1 = CameraFrame(only3.rgb, only3.depth, K, 0.0, np.eye(4))
    frame2 = CameraFrame(both.rgb, both.depth, K, 0.1, np.eye(4))
    assert [o.id for o in observe_markers(frame1, det, ids={3})] == [3]
    assert [o.id for o in observe_markers(frame2, det, ids={8})] == [8]


def test_render_markers_view_depth_follows_each_marker_plane():
    T3 = look_at_marker(1.0, offset=(-0.2, 0.0))
    T8 = look_at_marker(1.5, offset=(0.25, 0.0))
    v = render_markers_view(K, [(T3, 3), (T8, 8)], L)
    u8 = round(K.fx * 0.25 / 1.5 + K.cx)
    u3 = round(K.fx * -0.2 / 1.0 + K.cx)
    assert v.depth[240, u3] == pytest.approx(1.0, abs=1e-3)
    assert v.depth[240, u8] == pytest.approx(1.5, abs=1e-3)
    # a marker facing away is not drawn
    away = look_at_marker(1.0, yaw=math.pi)
    assert np.isnan(render_markers_view(K, [(away, 5)], L).corners).all()


@pytest.mark.parametrize("fov, distance", [(0.5, 1.2081), (0.5, 1.2), (1.2, 0.7)])
def test_exactly_fronto_parallel_marker_has_a_finite_pose(fov, distance):
    """IPPE_SQUARE returns NaN (or a pose tilted by degrees) for a perfectly square view
    on the optical axis (exact synthetic corners); the pose must still be finite and right."""
    from mmexec.skills.perception.markers import marker_pose_candidates

    Ks = CameraIntrinsics.from_fov(320, 240, fov)
    h = 0.05 * Ks.fx / distance
    c = np.array([[Ks.cx - h, Ks.cy - h], [Ks.cx + h, Ks.cy - h], [Ks.cx + h, Ks.cy + h], [Ks.cx - h, Ks.cy + h]],
                 np.float32)
    T, err = marker_pose_candidates(c, Ks, 0.10)[0]
    assert np.isfinite(T).all() and err < 0.01
    assert T[:3, 3] == pytest.approx([0.0, 0.0, distance], abs=1e-3)
    assert math.degrees(rotation_angle(T[:3, :3], np.diag([1.0, -1.0, -1.0]))) < 0.5
