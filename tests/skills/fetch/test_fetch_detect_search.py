"""detect_marker and search on the mock backend with synthetic marker frames."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fetchkit import events_of, marker_pose, run_skill

from mmexec.skills.base import FailureKind, SkillStatus
from mmexec.skills.perception.detect import WORLD_MARKERS
from mmexec.skills.search import WORLD_SEARCH


def _deg(headings: list[float]) -> list[int]:
    return [round(math.degrees(h)) for h in headings]


def assert_headings(headings: list[float], expected_deg: list[float], tol_deg: float = 4.0) -> None:
    """Base headings [rad] match ``expected_deg`` one for one within the turn tolerance."""
    assert len(headings) == len(expected_deg), _deg(headings)
    for h, e in zip(headings, expected_deg):
        err = math.degrees(math.atan2(math.sin(h - math.radians(e)), math.cos(h - math.radians(e))))
        assert abs(err) <= tol_deg, (_deg(headings), expected_deg)


def test_detect_marker_in_view_outputs_the_map_pose(fetch_robot, fetch_ctx):
    T = marker_pose(2.2, 1.1, 0.5, math.pi)  # 1.2 m ahead, facing the robot
    fetch_robot.camera.markers = {3: T}
    run = run_skill(fetch_ctx, "detect_marker", {"marker": 3})
    assert run.status is SkillStatus.SUCCESS, run.failure
    x, y, z, yaw = run.outputs["pose"]
    assert (x, y, z) == pytest.approx((2.2, 1.1, 0.5), abs=0.02)
    assert math.cos(yaw - math.pi) > math.cos(math.radians(5))
    assert run.outputs["distance"] == pytest.approx(math.hypot(1.2, 0.1), abs=0.03)
    est = fetch_ctx.world[WORLD_MARKERS][3]
    assert est.samples == 2 and np.allclose(est.T_map_marker[:3, 3], T[:3, 3], atol=0.02)
    assert len(fetch_robot.camera.headings) == 2  # profile detect_frames
    assert [f["marker"] for f in events_of(fetch_ctx, "marker_estimate")] == [3]


def test_detect_marker_not_in_view_spends_one_frame(fetch_robot, fetch_ctx):
    fetch_robot.camera.markers = {4: marker_pose(2.2, 1.0, 0.5, math.pi)}
    run = run_skill(fetch_ctx, "detect_marker", {"marker": 3})
    assert run.status is SkillStatus.FAILURE
    assert run.failure.kind is FailureKind.PRECONDITION and run.failure.reason == "marker 3 not in view"
    assert len(fetch_robot.camera.headings) == 1
    # the other marker seen was recorded in the world model anyway
    assert set(fetch_ctx.world[WORLD_MARKERS]) == {4}


def test_detect_marker_too_far_and_camera_silent(fetch_robot, fetch_ctx):
    fetch_robot.camera.markers = {3: marker_pose(3.0, 1.0, 0.5, math.pi)}
    run = run_skill(fetch_ctx, "detect_marker", {"marker": 3, "max_distance": 1.0})
    assert run.failure.kind is FailureKind.PRECONDITION and "farther than 1 m" in run.failure.reason
    fetch_robot.camera.enabled = False
    t0 = fetch_robot.clock.now()
    run = run_skill(fetch_ctx, "detect_marker", {"marker": 3})
    assert run.failure.kind is FailureKind.EXECUTION and "no frame" in run.failure.reason
    assert 2.0 <= fetch_robot.clock.now() - t0 <= 2.2


def test_search_turns_clockwise_in_30_degree_steps_and_stops_when_found(fetch_robot, fetch_ctx):
    # straight to the robot's right (clockwise 90 deg); the 0.5 rad camera does not see it
    # from the 60 degree view, so exactly four views are checked at the start location
    fetch_robot.camera.markers = {5: marker_pose(1.0, 0.2, 0.5, math.pi / 2)}
    run = run_skill(fetch_ctx, "search", {"marker": 5})
    assert run.status is SkillStatus.SUCCESS, run.failure
    # one frame per empty view, then detect_frames (2) frames of the found view
    assert_headings(fetch_robot.camera.headings, [0, -30, -60, -90, -90])
    assert run.outputs["views"] == 4
    # stopped at once: no turn after the marker was found
    assert abs(fetch_robot.base.pose.theta + math.pi / 2) < 0.05
    assert fetch_robot.base.pose.distance_to(fetch_robot.base.pose.__class__(1.0, 1.0, 0.0)) < 0.01
    prog = fetch_ctx.world[WORLD_SEARCH]
    assert prog.views == 4 and prog.locations_visited == 0 and prog.found_at is not None
    assert [e["views"] for e in events_of(fetch_ctx, "search_found")] == [4]


def test_search_full_turn_then_next_location(fetch_robot, fetch_ctx):
    # only visible from the first search location (4, 1), facing +x there
    fetch_robot.camera.markers = {6: marker_pose(5.2, 1.0, 0.5, math.pi)}
    fetch_robot.camera.max_range = 2.0  # not from the start, 4.2 m away
    run = run_skill(fetch_ctx, "search", {"marker": 6})
    assert run.status is SkillStatus.SUCCESS, run.failure
    full_turn = [0, -30, -60, -90, -120, -150, 180, 150, 120, 90, 60, 30]
    # then the first view at the location (heading 0) finds it
    assert_headings(fetch_robot.camera.headings, full_turn + [0, 0])
    assert run.outputs["views"] == 13
    assert fetch_ctx.world[WORLD_SEARCH].locations_visited == 1
    pose = fetch_robot.base.pose
    assert abs(pose.x - 4.0) < 0.06 and abs(pose.y - 1.0) < 0.06
    assert "to_goal" in [e["status"] for e in events_of(fetch_ctx, "base_status")]


def test_search_not_found_anywhere_fails_after_every_location(fetch_robot, fetch_ctx):
    fetch_robot.camera.markers = {}
    run = run_skill(fetch_ctx, "search", {"marker": 9, "max_locations": 1})
    assert run.status is SkillStatus.FAILURE
    assert run.failure.kind is FailureKind.EXECUTION
    assert run.failure.reason == "marker 9 not found: 24 views at 2 locations"
    full_turn = [0, -30, -60, -90, -120, -150, 180, 150, 120, 90, 60, 30]
    assert_headings(fetch_robot.camera.headings, full_turn + full_turn)



def test_search_skips_a_location_it_has_no_path_to(fetch_robot, fetch_ctx):
    """The first search location (4, 1) is walled in: no path, so the search goes on to
    the second (4, 4) instead of failing, and says which one it skipped."""
    from fetchkit import room_grid

    fetch_robot.occupancy = room_grid(boxes=[(3.3, 0.3, 4.7, 0.45), (3.3, 1.55, 4.7, 1.7),
                                             (3.3, 0.3, 3.45, 1.7), (4.55, 0.3, 4.7, 1.7)])
    # visible only from the second location (4, 4), which faces -x there
    fetch_robot.camera.markers = {6: marker_pose(2.8, 4.0, 0.5, 0.0)}
    fetch_robot.camera.max_range = 1.5
    run = run_skill(fetch_ctx, "search", {"marker": 6})
    assert run.status is SkillStatus.SUCCESS, run.failure
    [skipped] = events_of(fetch_ctx, "search_skipped")
    assert skipped["location"] == "search location 1" and "no path" in skipped["reason"]
    assert fetch_ctx.world[WORLD_SEARCH].locations_visited == 1
    pose = fetch_robot.base.pose
    assert abs(pose.x - 4.0) < 0.06 and abs(pose.y - 4.0) < 0.06
    # and with nothing to find, the failure names the unreachable location
    fetch_robot.camera.markers = {}
    fetch_ctx.events.clear()
    run = run_skill(fetch_ctx, "search", {"marker": 9})
    assert run.status is SkillStatus.FAILURE and run.failure.kind is FailureKind.EXECUTION
    assert run.failure.reason.endswith("(1 unreachable: search location 1)"), run.failure.reason

def test_search_step_is_a_parameter(fetch_robot, fetch_ctx):
    fetch_robot.camera.markers = {}
    run = run_skill(fetch_ctx, "search", {"marker": 9, "step": 90.0, "max_locations": 0})
    assert run.failure.reason == "marker 9 not found: 4 views at 1 locations"
    assert_headings(fetch_robot.camera.headings, [0, -90, 180, 90])
