"""The pick's pre-grasp is planned to an IK solution the straight grasp approach can start
from (skills/fetch/arm.py, ``_plan_pre_grasp``): on the UR3e's planning model (no robot,
no physics), before the lab's near shelf, lower board (marker 4), the base 0.75 m from
the marker. There the first solution (IK from the look pose, as the pick seeds it) is the
shoulder-down family whose straight line to the grasp has no IK before the box (the UR3e
lab crowd trial 8 and the seed-269668801 replays: 'joint jump' / 'forearm vs
mobile_base_link at 86 %'); the pre-grasp is planned to the other family instead."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from mmexec.drivers.descriptions import get
from mmexec.drivers.geometry import wrap_angle
from mmexec.sim.world import load_world
from mmexec.skills.fetch.arm import _plan_pre_grasp
from mmexec.skills.manipulation.grasp import grasp_poses
from mmexec.skills.manipulation.kinematics import ArmKinematics
from mmexec.skills.manipulation.planner import ArmPlanner, PlannerConfig
from mmexec.skills.manipulation.scene import ArmModel, PlanningScene

LOOK = [0.0, -1.2, 2.5, -4.1, -1.5708, 0.0]  # config/ur3e_sim.yaml named pose look
ITEM = (0.06, 0.06, 0.06)


@pytest.fixture(scope="module")
def ur3e():
    desc = get("ur3e_robotiq")
    kin = ArmKinematics.from_description(desc, tcp_offset=0.155)  # config/ur3e_sim.yaml arm.tcp_offset
    scene = PlanningScene(ArmModel.from_description(desc))
    mount = np.eye(4)
    mount[:3, 3] = desc.arm_mount
    with scene:
        yield SimpleNamespace(kin=kin, scene=scene, planner=ArmPlanner(scene, kin, PlannerConfig()), mount=mount)


def _set_up(ws, marker: int, distance: float, world_name: str = "lab"):
    """The base ``distance`` [m] straight in front of ``marker`` of the unrandomised world,
    facing it; the scene's static boxes and the item; returns the grasp poses (arm base),
    the item's pose and the pick's IK seed (the look pose turned to the target)."""
    world = load_world(world_name)
    name = next(n for n in world.item_names() if world.marker_of(n) == marker)
    T_item_map = world.item_poses[name]
    n = T_item_map[:3, 0].copy()
    n[2] = 0.0
    n /= np.linalg.norm(n)
    up = np.array([0.0, 0.0, 1.0])
    T_marker = np.eye(4)
    T_marker[:3, 0], T_marker[:3, 1], T_marker[:3, 2] = np.cross(up, n), up, n
    T_marker[:3, 3] = T_item_map[:3, 3] + n * ITEM[0] / 2
    yaw = math.atan2(-n[1], -n[0])
    T_map_base = np.eye(4)
    T_map_base[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    T_map_base[:2, 3] = T_marker[:2, 3] + n[:2] * distance
    T_am = np.linalg.inv(T_map_base @ ws.mount)
    ws.scene.set_static_boxes(world.scene_boxes(), T_am)
    for old in list(ws.scene.items):
        ws.scene.remove_item(old)
    T_item = T_am @ T_item_map
    ws.scene.add_item("item", ITEM, T_item)
    poses = grasp_poses(T_am @ T_marker, ws.kin.approach_axis, pre_grasp=(0.0, 0.0, 0.1), grasp_depth=0.03,
                        retract=(0.0, 0.1, 0.1), grasp_height=0.016)  # config/ur3e_sim.yaml fetch section
    bearing = math.atan2(poses.pre_grasp[1, 3], poses.pre_grasp[0, 3])
    p = ws.kin.fk(LOOK)[:3, 3]
    seed = [LOOK[0] + wrap_angle(bearing - math.atan2(p[1], p[0])), *LOOK[1:]]
    return poses, T_item, seed


def test_the_pre_grasp_goes_to_the_family_the_straight_approach_is_free_from(ur3e):
    poses, T_item, seed = _set_up(ur3e, 4, 0.75)
    # the solution plan_to_pose would take (the seed's): its straight approach fails
    first = ur3e.planner.plan_to_pose(LOOK, poses.pre_grasp, ik_seeds=[seed])
    assert first.success
    ur3e.scene.remove_item("item")
    line = ur3e.planner.cartesian_path(first.path[-1], poses.grasp)
    assert not line.success and "% of the straight line" in line.reason
    ur3e.scene.add_item("item", ITEM, T_item)

    changed: list[tuple[int, str]] = []
    res = _plan_pre_grasp(ur3e, LOOK, poses, [seed], ur3e.planner.config, "item", ITEM, T_item, changed)
    assert res.success, res.reason
    assert len(changed) == 1 and changed[0][0] > 1 and changed[0][1] == line.reason
    q_pre = np.array(res.path[-1])
    assert ur3e.kin.fk(q_pre)[:3, 3] == pytest.approx(poses.pre_grasp[:3, 3], abs=1e-3)
    assert float(np.max(np.abs(q_pre - np.array(first.path[-1])))) > 0.5  # another family
    assert "item" in ur3e.scene.items  # the item is back in the scene for the pre-grasp motion
    # no joint turns further than half a turn where a whole turn less reaches the same pose
    # (from the look pose the IK gave wrist 1 +4.82 rad for -1.46 and wrist 3 -4.71 for +1.57)
    wraps = (ur3e.kin.upper - ur3e.kin.lower) >= 2 * math.pi
    assert np.all(np.abs(q_pre - np.array(LOOK))[wraps] <= math.pi + 1e-9)
    ur3e.scene.remove_item("item")
    approach = ur3e.planner.cartesian_path(q_pre, poses.grasp)
    assert approach.success, approach.reason
    # and the retract leaves from where the approach ends
    assert ur3e.planner.cartesian_path(approach.path[-1], poses.retract).success


def test_where_the_first_family_is_free_the_plan_is_plan_to_poses(ur3e):
    """The upper board (marker 6) from 0.74 m: the seed's solution already has a free
    approach and its joints are the turns nearest the start, so the goal is the one
    ``plan_to_pose`` takes (the LoCoBot's and the UR5e's picks, whose seeds' solutions
    are free, plan what they planned before)."""
    poses, T_item, seed = _set_up(ur3e, 6, 0.74)
    before = ur3e.planner.plan_to_pose(LOOK, poses.pre_grasp, ik_seeds=[seed])
    changed: list[tuple[int, str]] = []
    res = _plan_pre_grasp(ur3e, LOOK, poses, [seed], ur3e.planner.config, "item", ITEM, T_item, changed)
    assert before.success and res.success and not changed
    assert res.path[-1] == pytest.approx(before.path[-1], abs=1e-12)
    assert res.path == before.path


def test_no_free_approach_from_any_solution_fails_before_the_arm_moves(ur3e):
    """Out of reach for the straight approach (0.84 m before the lower board): PLANNING
    'grasp approach: ...' from the pre-grasp plan, naming how many solutions were tried."""
    poses, T_item, seed = _set_up(ur3e, 4, 0.84)
    res = _plan_pre_grasp(ur3e, LOOK, poses, [seed], ur3e.planner.config, "item", ITEM, T_item)
    assert not res.success
    assert res.reason.startswith("grasp approach: ")
    assert "IK solutions of the pre-grasp)" in res.reason
    assert res.trajectory is None


def test_the_close_look_aims_the_camera_at_the_marker_centre():
    """``_camera_aimed``: the camera pose of the pick's close look (an estimate from far,
    a camera on the arm): DIST out along the marker's normal, UP higher, optical z through
    the marker's centre, x horizontal before the roll."""
    from mmexec.skills.fetch.arm import _camera_aimed

    T_marker = np.eye(4)  # upright, its normal along map -x
    T_marker[:3, 0], T_marker[:3, 1], T_marker[:3, 2] = [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]
    T_marker[:3, 3] = [1.0, 0.5, 0.3]
    for roll in (0.0, math.pi, math.pi / 2):
        T = _camera_aimed(T_marker, 0.35, 0.05, roll)
        assert T[:3, :3] @ T[:3, :3].T == pytest.approx(np.eye(3), abs=1e-12)
        assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
        assert T[:3, 3] == pytest.approx([0.65, 0.5, 0.35])
        ray = T_marker[:3, 3] - T[:3, 3]
        assert np.cross(T[:3, 2], ray) == pytest.approx(np.zeros(3), abs=1e-12) and T[:3, 2] @ ray > 0
        if roll == 0.0:
            assert T[2, 0] == pytest.approx(0.0, abs=1e-12)  # x horizontal
            assert T[2, 1] < 0  # image y (down) points down
