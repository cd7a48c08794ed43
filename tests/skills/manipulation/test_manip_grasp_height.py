"""Grasp height: every pick and place pose moves along the marker's y (up) by the same
amount, so the approach stays along the face normal and the release point is kept."""

from __future__ import annotations

import numpy as np
import pytest

from mmexec.skills.fetch.profile import DepotSettings, FetchProfile
from mmexec.skills.manipulation.grasp import grasp_poses, place_poses


def _marker() -> np.ndarray:
    # marker facing -x of the map (a shelf on the far wall), 0.53 m up
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2] = (0.0, -1.0, 0.0), (0.0, 0.0, 1.0), (-1.0, 0.0, 0.0)
    T[:3, 3] = (4.665, 2.0, 0.53)
    return T


@pytest.mark.parametrize("axis", [0, 2])
def test_grasp_height_raises_all_pick_poses_along_marker_up(axis: int) -> None:
    base = grasp_poses(_marker(), axis, grasp_depth=0.03, retract=(0.0, 0.10, 0.10))
    high = grasp_poses(_marker(), axis, grasp_depth=0.03, retract=(0.0, 0.10, 0.10), grasp_height=0.016)
    for a, b in ((base.pre_grasp, high.pre_grasp), (base.grasp, high.grasp), (base.retract, high.retract)):
        assert np.allclose(b[:3, 3] - a[:3, 3], (0.0, 0.0, 0.016))  # marker y is map z here
        assert np.allclose(a[:3, :3], b[:3, :3])
    # the grasp point is 3 cm behind the face and 16 mm above the marker centre
    assert np.allclose(high.grasp[:3, 3], (4.695, 2.0, 0.546))
    # the straight approach is still along the face normal (pure -x in map)
    d = high.grasp[:3, 3] - high.pre_grasp[:3, 3]
    assert np.allclose(d / np.linalg.norm(d), (1.0, 0.0, 0.0))


def test_place_with_grasp_height_releases_the_item_centre_at_the_place_point() -> None:
    T = _marker()
    p0 = place_poses(T, 2)
    p1 = place_poses(T, 2, grasp_height=0.016)
    assert np.allclose(p1.place[:3, 3] - p0.place[:3, 3], (0.0, 0.0, 0.016))
    assert np.allclose(p1.retract[:3, 3] - p0.retract[:3, 3], (0.0, 0.0, 0.016))


def test_profile_grasp_height_and_refine_at_are_checked() -> None:
    from mmexec.skills.navigation.navigate import NavSettings

    depot = DepotSettings((0.0, 0.0, 0.0), (0.0, 0.0, 0.3))
    assert FetchProfile(depot=depot).grasp_height == 0.0  # the seed's poses unless a profile says otherwise
    assert NavSettings().refine_at == 0.8
    bad = FetchProfile(depot=depot, grasp_height=0.04).validate()
    assert any("grasp_height" in m for m in bad)
    # refine_at > 0 is a declared range of the profile schema, checked where the value is written
    from mmexec.config.yamlload import Problems, load_yaml_text
    from mmexec.skills.profile import PROFILE

    raw = load_yaml_text("max_v: 0.5\nrefine_at: 0.0\n", "c.yaml")
    problems = Problems()
    assert PROFILE.bind_section("nav", raw, raw.mark, problems) is None
    assert [str(p) for p in problems] == ["c.yaml:2:12: profile.nav.refine_at: expected > 0 m, got 0.0"]
    assert FetchProfile(depot=depot, grasp_height=0.016).validate() == []
