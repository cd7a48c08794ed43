"""The fetch mission's way to a marker whose front is blocked (skills/fetch/holistic.py):
the marker's grasp frame handed to the holistic planner is the frame the pick grasps in,
and the second look at the marker from where the base stopped (mock base and a camera
rendering synthetic ArUco frames)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fetchkit import events_of, marker_pose, run_skill

from mmexec.skills.base import FailureKind, SkillStatus
from mmexec.skills.fetch.holistic import WORLD_GRASP_FRAME, marker_grasp_transform
from mmexec.skills.manipulation import grasp_poses
from mmexec.skills.manipulation.holistic_skill import grasp_frame
from mmexec.skills.perception.detect import WORLD_MARKERS, MarkerEstimate


@pytest.mark.parametrize("yaw", [math.pi, 0.3, -2.0])
def test_the_marker_grasp_frame_is_the_holistic_front_frame_at_the_picks_grasp_point(yaw):
    """An upright marker facing ``yaw``: its grasp frame is holistic_standoff's front
    grasp frame (z towards the gripper, y up) at the point grasp_depth behind the face
    and grasp_height up, and the pre-grasp and grasp tool poses the holistic planner
    derives from it (no depth, no height) are the pick's from the marker itself."""
    T_marker = marker_pose(2.0, 1.0, 0.3, yaw)
    depth, height = 0.03, 0.016
    T = marker_grasp_transform(T_marker, depth, height)
    point = (2.0 - depth * math.cos(yaw), 1.0 - depth * math.sin(yaw), 0.3 + height)
    assert T == pytest.approx(grasp_frame(point, "front", yaw), abs=1e-12)
    for axis in (0, 2):  # the WX250s's approach is the tool's x, the UR's its z
        holistic = grasp_poses(T, axis, pre_grasp=(0.0, 0.0, 0.1))
        pick = grasp_poses(T_marker, axis, pre_grasp=(0.0, 0.0, 0.1), grasp_depth=depth, grasp_height=height)
        assert holistic.grasp == pytest.approx(pick.grasp, abs=1e-12)
        # the pick's pre-grasp is 0.1 m out of the face, the holistic one 0.1 m from the grasp point
        assert holistic.pre_grasp[:3, 3] - pick.pre_grasp[:3, 3] == pytest.approx(-depth * T_marker[:3, 2], abs=1e-12)


def test_marker_grasp_frame_puts_the_frame_in_the_world_model_and_outputs_the_item(fetch_robot, fetch_ctx):
    T = marker_pose(2.0, 1.0, 0.25, math.pi)
    fetch_ctx.world[WORLD_MARKERS] = {4: MarkerEstimate(4, T, 3, 0.0, 1.5)}
    fetch_robot.profile["fetch"].update(item_size=[0.06, 0.05, 0.08], grasp_depth=0.03, grasp_height=0.01)
    run = run_skill(fetch_ctx, "marker_grasp_frame", {"marker": 4})
    assert run.status is SkillStatus.SUCCESS, run.failure
    assert fetch_ctx.world[WORLD_GRASP_FRAME] == pytest.approx(marker_grasp_transform(T, 0.03, 0.01))
    # along the marker's x (right), y (up), z (out of the face): width, height, depth
    assert run.outputs == {"size": [0.05, 0.08, 0.06], "object_size": [0.06, 0.05, 0.08], "back_off": 0.1}
    run = run_skill(fetch_ctx, "marker_grasp_frame", {"marker": 5})
    assert run.failure.kind is FailureKind.PRECONDITION and "no estimate of marker 5" in run.failure.reason


def test_relocate_marker_replaces_the_estimate_from_where_the_base_stands(fetch_robot, fetch_ctx):
    """The marker in view from the base's pose: the new estimate (from this pose)
    replaces the far one; out of view: the old one stays, and the skill says so."""
    true = marker_pose(2.2, 1.1, 0.5, math.pi)
    old = true.copy()
    old[:3, 3] += (0.0, 0.03, 0.0)  # the search's far estimate, 3 cm off
    fetch_ctx.world[WORLD_MARKERS] = {3: MarkerEstimate(3, old, 3, 0.0, 2.0)}
    fetch_robot.camera.markers = {3: true}
    run = run_skill(fetch_ctx, "relocate_marker", {"marker": 3})
    assert run.status is SkillStatus.SUCCESS and run.outputs == {"seen": True}
    est = fetch_ctx.world[WORLD_MARKERS][3]
    assert np.allclose(est.T_map_marker[:3, 3], true[:3, 3], atol=0.01)
    assert est.distance == pytest.approx(math.hypot(1.2, 0.1), abs=0.03)
    assert [e["marker"] for e in events_of(fetch_ctx, "marker_estimate")] == [3]

    fetch_robot.camera.markers = {}
    run = run_skill(fetch_ctx, "relocate_marker", {"marker": 3})
    assert run.status is SkillStatus.SUCCESS and run.outputs == {"seen": False}
    assert fetch_ctx.world[WORLD_MARKERS][3] is est
    assert events_of(fetch_ctx, "marker_not_relocated") == [{"marker": 3, "aimed": False, "node": ""}]
    run = run_skill(fetch_ctx, "relocate_marker", {"marker": 9})
    assert run.failure.kind is FailureKind.PRECONDITION
