"""The declarative robot-profile schema (mmexec.skills.profile): ranges, hints, base poses,
and the fetch package's section declared through it."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from mmexec.config.yamlload import load_yaml_text
from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import SkillContext, SkillFailure
from mmexec.skills.fetch.common import FetchProfile, fetch_profile, nav_margin
from mmexec.skills.profile import PROFILE, Bounds, ProfileSchema, setting


def _profile(text: str):
    return load_yaml_text(text, "c.yaml")["profile"]


def _problems(text: str) -> list[str]:
    """The problems PROFILE.check finds in the config text's profile, sorted."""
    raw = _profile(text)
    return sorted(map(str, PROFILE.check(raw, raw.mark)[1]))


@pytest.mark.parametrize("bounds, text", [
    (Bounds(gt=0), "> 0"), (Bounds(ge=0), ">= 0"), (Bounds(lt=5), "< 5"), (Bounds(le=5), "<= 5"),
    (Bounds(gt=0, le=1), "in (0, 1]"), (Bounds(ge=1, le=180), "in [1, 180]"), (Bounds(ge=0, lt=1), "in [0, 1)"),
])
def test_bounds_describe_themselves(bounds: Bounds, text: str) -> None:
    assert bounds.describe() == text


def test_bounds_reject_non_finite_values() -> None:
    b = Bounds(gt=0)
    assert b.admits(1.0) and not b.admits(0.0)
    assert not b.admits(float("nan")) and not b.admits(float("inf"))


def test_the_fetch_section_is_declared_by_the_fetch_package() -> None:
    section = PROFILE.sections()["fetch"]
    assert section.schema is FetchProfile and section.package == "mmexec.skills.fetch"
    assert {"home", "places", "named_poses"} <= set(PROFILE.sections())


def test_ranges_are_located_at_each_value_and_list_item() -> None:
    assert _problems("profile:\n  fetch:\n    depot: {base: [1, 2, 0], place: [1, 2, 0.3]}\n"
                     "    approach_distances: [0.3, -0.1]\n    nav: {max_v: 0, margin: -0.5}\n") == [
        "c.yaml:4:31: profile.fetch.approach_distances[1]: expected > 0 m, got -0.1",
        "c.yaml:5:18: profile.fetch.nav.max_v: expected > 0 m/s, got 0",
        "c.yaml:5:29: profile.fetch.nav.margin: expected >= 0 m, got -0.5",
    ]


def test_a_valid_profile_binds_every_section() -> None:
    raw = _profile("profile:\n  home: [1, 2, 0]\n  named_poses: {sleep: [0, 0.5]}\n"
                   "  fetch:\n    depot: {base: [1, 2, 0], place: [1, 2, 0.3]}\n    nav: {margin: 0.1}\n")
    bound, problems = PROFILE.check(raw, raw.mark)
    assert not problems
    assert bound["home"] == (1.0, 2.0, 0.0) and bound["named_poses"] == {"sleep": [0.0, 0.5]}
    assert isinstance(bound["fetch"], FetchProfile) and bound["fetch"].nav.margin == 0.1
    assert nav_margin(raw) == 0.1
    assert nav_margin({}) == FetchProfile.__dataclass_fields__["nav"].default.margin


def test_base_poses_are_every_declared_pose_in_file_order() -> None:
    raw = _profile("profile:\n  home: [1, 2, 0]\n  places: {a: [3, 4, 0], bad: [1, 2]}\n"
                   "  fetch:\n    search_locations: [[5, 6, 1], [7, 8, 2]]\n"
                   "    depot: {base: [9, 10, 3], place: [1, 2, 0.3]}\n")
    poses = PROFILE.base_poses(raw, raw.mark)
    assert [(p.path, p.mark.line, p.pose) for p in poses] == [
        ("profile.home", 2, Pose2D(1, 2, 0)),
        ("profile.places.a", 3, Pose2D(3, 4, 0)),
        ("profile.fetch.search_locations[0]", 5, Pose2D(5, 6, 1)),
        ("profile.fetch.search_locations[1]", 5, Pose2D(7, 8, 2)),
        ("profile.fetch.depot.base", 6, Pose2D(9, 10, 3)),
    ]


def test_a_section_declared_again_must_keep_its_schema() -> None:
    @dataclass(frozen=True)
    class Dock:
        speed: float = setting(0.1, unit="m/s", gt=0, le=0.5, doc="docking speed")

    schema = ProfileSchema()
    first = schema.declare("dock", Dock, package="my_lab.dock", doc="docking")
    assert schema.declare("dock", Dock, package="my_lab.other", doc="docking") is first
    with pytest.raises(ValueError, match="'dock' is already declared by my_lab.dock"):
        schema.declare("dock", float, package="my_lab.other", doc="docking")
    raw = _profile("profile:\n  dock: {speed: 0.9}\n  dok: {}\n")
    _bound, problems = schema.check(raw, raw.mark)
    assert sorted(map(str, problems)) == [
        "c.yaml:2:17: profile.dock.speed: expected in (0, 0.5] m/s, got 0.9",
        "c.yaml:3:3: profile.dok: unknown profile section; did you mean 'dock'?",
    ]


def test_a_profile_set_up_in_code_fails_the_skill_with_the_range_problem(mock_robot) -> None:
    mock_robot.profile["fetch"] = {"depot": {"base": [0, 0, 0], "place": [0, 0, 0.3]}, "detect_frames": 0}
    with pytest.raises(SkillFailure, match=r"profile.fetch.detect_frames: expected >= 1, got 0"):
        fetch_profile(SkillContext.for_robot(mock_robot))


def test_named_pose_roles_must_name_a_named_pose_defaults_included() -> None:
    assert _problems("profile:\n  named_poses: {tuck: [0, 0], carry: [0, 1]}\n"
                     "  fetch:\n    depot: {base: [1, 2, 0], place: [1, 2, 0.3]}\n"
                     "    arm: {stow: tuk, carry: carry, look: gaze}\n") == [
        "c.yaml:5:17: profile.fetch.arm.stow: 'tuk' is not one of profile.named_poses; did you mean 'tuck'?",
        "c.yaml:5:42: profile.fetch.arm.look: 'gaze' is not one of profile.named_poses (known: carry, tuck)",
    ]
    assert _problems("profile:\n  named_poses: {tuck: [0, 0]}\n"
                     "  fetch:\n    depot: {base: [1, 2, 0], place: [1, 2, 0.3]}\n    arm: {stow: tuck}\n") == [
        "c.yaml:5:10: profile.fetch.arm.carry: 'sleep' (the default) is not one of profile.named_poses (known: tuck)"]


def test_a_named_pose_typo_is_reported_with_the_other_problems_of_its_section() -> None:
    assert _problems("profile:\n  named_poses: {tuck: [0, 0]}\n"
                     "  fetch:\n    depot: {base: [1, 2, 0], place: [1, 2, 0.3]}\n"
                     "    detect_frames: 0\n    arm: {stow: tuk}\n") == [
        "c.yaml:5:20: profile.fetch.detect_frames: expected >= 1, got 0",
        "c.yaml:6:17: profile.fetch.arm.stow: 'tuk' is not one of profile.named_poses; did you mean 'tuck'?",
    ]
