"""The declarative robot-profile schema (mmexec.skills.profile): ranges, hints, base poses,
moved settings, and the sections the general skills and the fetch package declare."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from mmexec.config.yamlload import load_yaml_text
from mmexec.drivers.interfaces import Pose2D
from mmexec.skills.base import SkillContext, SkillFailure
from mmexec.skills.fetch.profile import FetchProfile, fetch_profile
from mmexec.skills.manipulation.arm import ArmSettings
from mmexec.skills.navigation.navigate import NavSettings, nav_margin
from mmexec.skills.perception.detect import CameraSettings, camera_settings
from mmexec.skills.profile import PROFILE, Bounds, ProfileSchema, section, setting
from mmexec.skills.search import SearchSettings


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


@pytest.mark.parametrize("key, schema, package", [
    ("fetch", FetchProfile, "mmexec.skills.fetch"),
    ("nav", NavSettings, "mmexec.skills.navigation.navigate"),
    ("arm", ArmSettings, "mmexec.skills.manipulation.arm"),
    ("camera", CameraSettings, "mmexec.skills.perception.detect"),
    ("search", SearchSettings, "mmexec.skills.search"),
])
def test_each_section_is_declared_by_the_package_that_reads_it(key: str, schema: type, package: str) -> None:
    declared = PROFILE.sections()[key]
    assert declared.schema is schema and declared.package == package
    assert {"home", "places", "named_poses"} <= set(PROFILE.sections())


def test_ranges_are_located_at_each_value_and_list_item() -> None:
    assert _problems("profile:\n  nav:\n    approach_distances: [0.3, -0.1]\n    max_v: 0\n    margin: -0.5\n") == [
        "c.yaml:3:31: profile.nav.approach_distances[1]: expected > 0 m, got -0.1",
        "c.yaml:4:12: profile.nav.max_v: expected > 0 m/s, got 0",
        "c.yaml:5:13: profile.nav.margin: expected >= 0 m, got -0.5",
    ]


def test_a_valid_profile_binds_every_section() -> None:
    raw = _profile("profile:\n  home: [1, 2, 0]\n  named_poses: {sleep: [0, 0.5]}\n  nav: {margin: 0.1}\n"
                   "  camera: {detect_frames: 5}\n  fetch:\n    depot: {base: [1, 2, 0], place: [1, 2, 0.3]}\n")
    bound, problems = PROFILE.check(raw, raw.mark)
    assert not problems
    assert bound["home"] == (1.0, 2.0, 0.0) and bound["named_poses"] == {"sleep": [0.0, 0.5]}
    assert isinstance(bound["fetch"], FetchProfile) and bound["nav"].margin == 0.1
    assert bound["camera"] == CameraSettings(detect_frames=5)
    assert nav_margin(raw) == 0.1
    assert nav_margin({}) == NavSettings().margin


def test_a_section_the_profile_lacks_reads_as_its_defaults() -> None:
    assert section({}, "nav") == NavSettings() and section({"nav": None}, "search") == SearchSettings()
    raw = _profile("profile:\n  search: {step_deg: 45}\n")
    assert section(raw, "search") == SearchSettings(step_deg=45.0)
    assert section(raw, "search") is section(raw, "search")  # bound once per raw value


def test_base_poses_are_every_declared_pose_in_file_order() -> None:
    raw = _profile("profile:\n  home: [1, 2, 0]\n  places: {a: [3, 4, 0], bad: [1, 2]}\n"
                   "  search:\n    locations: [[5, 6, 1], [7, 8, 2]]\n"
                   "  fetch:\n    depot: {base: [9, 10, 3], place: [1, 2, 0.3]}\n")
    poses = PROFILE.base_poses(raw, raw.mark)
    assert [(p.path, p.mark.line, p.pose) for p in poses] == [
        ("profile.home", 2, Pose2D(1, 2, 0)),
        ("profile.places.a", 3, Pose2D(3, 4, 0)),
        ("profile.search.locations[0]", 5, Pose2D(5, 6, 1)),
        ("profile.search.locations[1]", 5, Pose2D(7, 8, 2)),
        ("profile.fetch.depot.base", 7, Pose2D(9, 10, 3)),
    ]


def test_a_setting_that_moved_out_of_fetch_is_located_with_its_new_place() -> None:
    """A config written before the general sections existed: each old key is one located
    problem naming where it lives now, and the rest of the section still binds."""
    assert _problems("profile:\n  fetch:\n    depot: {base: [1, 2, 0], place: [1, 2, 0.3]}\n"
                     "    search_locations: [[1, 2, 0]]\n    nav: {max_v: 0.5}\n    detect_frames: 3\n"
                     "    grasp_depth: -1\n") == [
        ("c.yaml:4:5: profile.fetch.search_locations: unknown key; did you mean 'profile.search.locations'? "
        "(the setting moved there)"),
        "c.yaml:5:5: profile.fetch.nav: unknown key; did you mean 'profile.nav'? (the setting moved there)",
        ("c.yaml:6:5: profile.fetch.detect_frames: unknown key; did you mean 'profile.camera.detect_frames'? "
        "(the setting moved there)"),
        "c.yaml:7:18: profile.fetch.grasp_depth: expected >= 0 m, got -1",
    ]
    # a top-level key that is a setting of a section gets that section's path
    assert _problems("profile:\n  tcp_offset: 0.155\n") == [
        "c.yaml:2:3: profile.tcp_offset: unknown profile section; did you mean 'arm.tcp_offset'?"]


def test_a_moved_setting_must_name_one_key_of_a_section() -> None:
    with pytest.raises(ValueError, match="SECTION.KEY"):
        ProfileSchema().move("fetch.nav.max_v", "nav.max_v")


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
    mock_robot.profile["camera"] = {"detect_frames": 0}
    mock_robot.profile["fetch"] = {"depot": {"base": [0, 0, 0], "place": [0, 0, 0.3]}, "search_locations": []}
    ctx = SkillContext.for_robot(mock_robot)
    with pytest.raises(SkillFailure, match=r"profile.camera.detect_frames: expected >= 1, got 0"):
        camera_settings(ctx)
    with pytest.raises(SkillFailure, match=r"profile.fetch.search_locations: unknown key; did you mean "
                                           r"'profile.search.locations'"):
        fetch_profile(ctx)
    del mock_robot.profile["fetch"]
    with pytest.raises(SkillFailure, match=r"no 'fetch:' section"):
        fetch_profile(ctx)


def test_named_pose_roles_must_name_a_named_pose_defaults_included() -> None:
    assert _problems("profile:\n  named_poses: {tuck: [0, 0], carry: [0, 1]}\n"
                     "  arm: {stow: tuk, carry: carry, look: gaze}\n") == [
        "c.yaml:3:15: profile.arm.stow: 'tuk' is not one of profile.named_poses; did you mean 'tuck'?",
        "c.yaml:3:40: profile.arm.look: 'gaze' is not one of profile.named_poses (known: carry, tuck)",
    ]
    assert _problems("profile:\n  named_poses: {tuck: [0, 0]}\n  arm: {stow: tuck}\n") == [
        "c.yaml:3:8: profile.arm.carry: 'sleep' (the default) is not one of profile.named_poses (known: tuck)"]


def test_a_named_pose_typo_is_reported_with_the_other_problems_of_its_section() -> None:
    assert _problems("profile:\n  named_poses: {tuck: [0, 0]}\n"
                     "  arm:\n    grasp_force: 0\n    stow: tuk\n") == [
        "c.yaml:4:18: profile.arm.grasp_force: expected > 0 N, got 0",
        "c.yaml:5:11: profile.arm.stow: 'tuk' is not one of profile.named_poses; did you mean 'tuck'?",
    ]
