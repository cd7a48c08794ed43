"""Reflector extraction, the triangle library and matching, trilateration and weights."""

from __future__ import annotations

import math

import numpy as np
import pytest
from locroom import POST_R, POSTS, Lidar

from mmexec.skills.localization.reflectors import (
    Detection,
    ReflectorConfig,
    TriangleLibrary,
    extract_reflectors,
    fix_from_scan,
    heading_from_bearings,
    match_reflectors,
    orientation_score,
    position_weight,
    trilaterate,
)

CFG = ReflectorConfig(post_radius=POST_R)


def _detections(pose: np.ndarray, pts: np.ndarray) -> list[Detection]:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    out = []
    for x, y in pts:
        dx, dy = x - pose[0], y - pose[1]
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        out.append(Detection(lx, ly, math.hypot(lx, ly), math.atan2(ly, lx), 5))
    return out


def test_library_holds_every_triangle_sorted_by_longest_side():
    lib = TriangleLibrary(POSTS)
    assert len(lib) == math.comb(len(POSTS), 3)
    longest = [s[0] for s in lib.sides]
    assert longest == sorted(longest)
    for (l1, l2, l3), (a, b, c) in zip(lib.sides, lib.vertices, strict=True):
        assert l1 >= l2 >= l3
        d = lambda i, j: float(np.hypot(*(POSTS[i] - POSTS[j])))
        assert d(a, b) == pytest.approx(l1) and d(a, c) == pytest.approx(l2) and d(b, c) == pytest.approx(l3)


def test_extraction_finds_each_visible_post_centre_within_a_centimetre():
    pose = np.array([2.0, 3.0, 0.7])
    lidar = Lidar(beams=1600, sigma=0.002)
    r, inten = lidar.scan(pose, np.random.default_rng(5))
    dets = extract_reflectors(r, lidar.angles, inten, CFG)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    found = np.array([[pose[0] + c * d.x - s * d.y, pose[1] + s * d.x + c * d.y] for d in dets])
    assert len(dets) >= 4
    for f in found:
        assert np.min(np.hypot(*(POSTS - f).T)) < 0.01


def test_a_post_under_a_single_beam_is_placed_behind_the_hit_without_bias():
    """A post narrower than a beam spacing shows in one beam; its centre is put pi/4 of the
    radius behind the hit, the mean depth under a beam crossing it at a random offset."""
    d, r = 5.0, 0.025
    offsets = np.linspace(-r, r, 201)[1:-1]  # lateral offset of the beam from the centre
    found = []
    for b in offsets:
        hit = d - math.sqrt(r * r - b * b)  # range to the surface along a beam at offset b
        ang = math.asin(b / d)
        dets = extract_reflectors(np.array([hit, 3.0]), np.array([ang, 1.0]), np.array([1.0, 0.2]),
                                  ReflectorConfig(post_radius=r))
        assert len(dets) == 1 and dets[0].beams == 1
        found.append((dets[0].x - d * math.cos(ang), dets[0].y))
    err = np.array(found)
    assert abs(err[:, 0].mean()) < 0.002  # unbiased along the beam (a full radius: +5.4 mm)
    assert np.abs(err).max() < r
    assert extract_reflectors(np.array([5.0]), np.array([0.0]), np.array([1.0]), ReflectorConfig(min_beams=2)) == []


def test_a_run_across_the_scan_seam_is_one_reflector():
    angles = -math.pi + np.arange(8) * (2 * math.pi / 8)
    ranges = np.full(8, 2.0)
    inten = np.array([1.0, 0, 0, 0, 0, 0, 0, 1.0])
    dets = extract_reflectors(ranges, angles, inten, ReflectorConfig(min_beams=2))
    assert len(dets) == 1
    assert abs(dets[0].bearing) == pytest.approx(math.pi, abs=0.5)


@pytest.mark.parametrize("drop", [(), (1,), (0, 4)])
def test_matching_is_exact_with_missing_reflectors_and_a_spurious_one(drop):
    lib = TriangleLibrary(POSTS)
    pose = np.array([2.5, 2.6, -0.9])
    keep = [i for i in range(len(POSTS)) if i not in drop]
    pts = np.vstack([POSTS[keep], [[4.2, 2.9]]])  # a shiny chair leg that is no reflector
    dets = _detections(pose, pts)
    got = match_reflectors(dets, lib, CFG)
    assert got == {n: keep[n] for n in range(len(keep))}


def test_two_detections_match_nothing():
    assert match_reflectors(_detections(np.zeros(3), POSTS[:2]), TriangleLibrary(POSTS), CFG) == {}


def test_trilateration_and_heading_recover_exact_geometry():
    pose = np.array([1.7, 2.2, 2.8])  # heading near pi: a plain mean of angles would break
    dets = _detections(pose, POSTS)
    xy, res = trilaterate(POSTS, np.array([d.range for d in dets]))
    assert xy == pytest.approx(pose[:2], abs=1e-9)
    assert res < 1e-9
    th = heading_from_bearings(xy, POSTS, np.array([d.bearing for d in dets]))
    assert th == pytest.approx(pose[2], abs=1e-9)


def test_fix_from_scan_with_a_mounted_lidar_gives_the_base_pose():
    base = np.array([4.0, 1.2, 1.1])
    mount = (0.1, -0.02, 0.05)
    c, s = math.cos(base[2]), math.sin(base[2])
    lidar_pose = np.array([base[0] + c * mount[0] - s * mount[1], base[1] + s * mount[0] + c * mount[1], base[2] + mount[2]])
    lidar = Lidar(beams=1600, sigma=0.0)
    r, inten = lidar.scan(lidar_pose, np.random.default_rng(6))
    fix = fix_from_scan(r, lidar.angles, inten, TriangleLibrary(POSTS), CFG, mount)
    assert fix is not None and len(fix.ids) >= 4
    assert fix.pose[:2] == pytest.approx(base[:2], abs=0.005)
    assert fix.pose[2] == pytest.approx(base[2], abs=0.005)


def test_weights_prefer_the_particle_at_the_fix():
    fix = np.array([1.0, 1.0, 0.5])
    parts = np.array([fix, fix + [0.05, 0, 0], fix + [0, 0, 0.1]])
    d = position_weight(parts, fix, CFG)
    assert d[0] > d[1] and d[0] > d[2]
    assert d[0] == pytest.approx(1 / ((2 * math.pi) ** 1.5 * CFG.sigma_xy**2 * CFG.sigma_theta))
    dets = _detections(fix, POSTS[:4])
    s = orientation_score(parts, POSTS[:4], np.array([x.bearing for x in dets]), CFG)
    assert s[0] > s[2]
    assert s[0] == pytest.approx(1 / (CFG.sigma_bearing * math.sqrt(2 * math.pi)))
