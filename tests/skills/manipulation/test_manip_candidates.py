from __future__ import annotations

import math

import numpy as np
import pytest

from mmexec.skills.manipulation.candidates import CandidateConfig, grasp_candidates, select_grasp
from mmexec.skills.manipulation.kinematics import wx250s

P = np.array([0.35, 0.20, 0.25])   # a fruit ahead-left of the arm base and above it


@pytest.mark.parametrize("approach_axis", [0, 2])
def test_candidates_on_the_vertical_plane_facing_the_barycentre(approach_axis):
    cfg = CandidateConfig(distance=0.05, pre_grasp_distance=0.1)
    c = grasp_candidates(P, approach_axis, cfg)
    assert len(c) == 50 and c.poses.shape == (50, 4, 4)
    np.testing.assert_allclose(c.thetas[[0, -1]], [-math.pi, math.pi / 3])
    n = np.array([-P[1], P[0], 0.0]) / math.hypot(P[0], P[1])   # normal of the vertical plane
    pos, pre = c.poses[:, :3, 3], c.pre_grasps[:, :3, 3]
    # tool origins at the grasp distance from the barycentre, in the plane through the base
    np.testing.assert_allclose(np.linalg.norm(pos - P, axis=1), 0.05, atol=1e-12)
    np.testing.assert_allclose(pos @ n, 0.0, atol=1e-12)
    np.testing.assert_allclose(pre @ n, 0.0, atol=1e-12)
    # the approach axis points from the tool to the barycentre; the pre-grasp is behind it
    a = c.poses[:, :3, approach_axis]
    np.testing.assert_allclose(a, (P - pos) / 0.05, atol=1e-12)
    np.testing.assert_allclose(c.approach, a, atol=1e-12)
    np.testing.assert_allclose(pre, pos - 0.1 * a, atol=1e-12)
    # proper rotations; the finger axis (y) is the plane's normal, horizontal
    R = c.poses[:, :3, :3]
    np.testing.assert_allclose(R.transpose(0, 2, 1) @ R, np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0)
    np.testing.assert_allclose(np.abs(R[:, :, 1] @ n), 1.0, atol=1e-12)


def test_theta_sweeps_from_behind_over_the_top_to_below():
    """-pi: from behind the object towards the base; -pi/2: straight down relative to the
    base-object line; 0: along it, from the base side; pi/3: from below at 60 degrees."""
    cfg = CandidateConfig(count=7, theta_range=(-math.pi, math.pi / 2))  # steps of pi/4
    c = grasp_candidates(P, 0, cfg)
    v_c = P / np.linalg.norm(P)
    np.testing.assert_allclose(c.approach[0], -v_c, atol=1e-12)
    np.testing.assert_allclose(c.approach[4], v_c, atol=1e-12)
    assert c.approach[2] @ v_c == pytest.approx(0.0, abs=1e-12) and c.approach[2][2] < -0.8   # top
    assert c.approach[6][2] > 0.8                                                          # bottom
    # the printed algorithm's y = (0, 0, 1) x x agrees wherever the approach points away
    # from the base (and the tool's z is then up)
    for k in (3, 4, 5):
        y = np.cross([0.0, 0.0, 1.0], c.poses[k, :3, 0])
        np.testing.assert_allclose(y / np.linalg.norm(y), c.poses[k, :3, 1], atol=1e-12)
    assert c.poses[4, 2, 2] > 0


def test_object_at_base_height_and_below_does_not_collapse():
    for z in (0.0, -0.2):
        c = grasp_candidates([0.4, 0.0, z], 0)
        top = np.argmin(np.abs(c.thetas + math.pi / 2))
        assert c.approach[top][2] < -0.8      # still a grasp from the top, never from below
        np.testing.assert_allclose(np.linalg.norm(c.approach, axis=1), 1.0)


def test_select_takes_a_quarter_of_the_reachable_list():
    c = grasp_candidates(P, 0, CandidateConfig(distance=0.05))
    seen = []

    def reachable(T):  # fake IK: no approach from behind (towards the base) nor from far below
        seen.append(T)
        a = T[:3, 0]
        ok = a @ P > 0 and a[2] < 0.5
        return np.full(6, len(seen), float) if ok else None

    choice = select_grasp(c, reachable)
    assert choice is not None and len(seen) == 50
    expected = [i for i in range(50) if c.approach[i] @ P > 0 and c.approach[i][2] < 0.5]
    assert list(choice.feasible) == expected
    assert choice.index == expected[len(expected) // 4]
    assert choice.theta == c.thetas[choice.index]
    np.testing.assert_array_equal(choice.pose, c.poses[choice.index])
    np.testing.assert_array_equal(choice.pre_grasp, c.pre_grasps[choice.index])
    assert choice.solution[0] == choice.index + 1    # the callback's answer for that pose
    assert select_grasp(c, reachable, pick_fraction=0.0).index == expected[0]
    assert select_grasp(c, lambda T: None) is None


def test_wx250s_ik_plugs_in():
    kin = wx250s()
    p = np.array([0.30, 0.05, 0.15])
    c = grasp_candidates(p, kin.approach_axis, CandidateConfig(count=12))
    choice = select_grasp(c, lambda T: kin.ik(T, attempts=6))
    assert choice is not None and len(choice.feasible) >= 3
    T = kin.fk(choice.solution)
    np.testing.assert_allclose(T[:3, 3], p, atol=1e-3)
    assert np.degrees(math.acos(min(1.0, T[:3, 0] @ choice.pose[:3, 0]))) < 1.0


def test_errors():
    with pytest.raises(ValueError, match="vertical axis"):
        grasp_candidates([0.0, 0.0, 0.4], 0)
    with pytest.raises(ValueError, match="approach_axis"):
        grasp_candidates(P, 1)
    with pytest.raises(ValueError, match="pick_fraction"):
        grasp_candidates(P, 0, CandidateConfig(pick_fraction=1.0))
    with pytest.raises(ValueError, match="pick_fraction"):
        select_grasp(grasp_candidates(P, 0), lambda T: None, pick_fraction=-0.1)
